"""Evaluation of the system and its parts, outside core/ (nothing here runs in the graph).

* `safety`: the safety score of docs/evaluation.md (warned in time, false alarm
  events per minute of walking, false reports per frame, recall), one implementation
  used by `asmonc run`, `asmonc eval` and `asmonc campaign`.
* `truth`: the world's true obstacles with their footprints, from a simulated scene or
  from a bag's ground-truth topics.
* `alarm_replay`: the alarm node's logic driven over a detector's outputs in bag time.
* Measurements behind the commands: `offline` (`asmonc eval`), `evaluation` (detections
  against ground truth per frame), `bench`, `fig5` with `detection_model`, `smallbox`,
  `gait_walks` / `gait_real` / `gait_bags` / `gait_figures` (`asmonc gait`), `motion_bags`
  with `motion_experiment` (`asmonc motion`), `fuzz`, `audio_bench`.
"""
