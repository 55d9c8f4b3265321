"""Evaluation of the system and its parts, outside core/ (nothing here runs in the graph).

* `evaluation`: detections against ground truth per frame and per sequence (recall,
  false reports, errors, path warnings); `safety`: the safety score of /shared
  EVALUATION.md; `truth`: the world's true obstacles with their footprints;
  `alarm_replay`: the alarm node's logic driven over a detector's outputs in bag time.
* Measurements behind the commands: `offline` (`asmonc eval`), `bench`, `fig5` with
  `detection_model`, `smallbox`, `gait_walks` / `gait_real` / `gait_bags` /
  `gait_figures` (`asmonc gait`), `motion_bags` with `motion_experiment`
  (`asmonc motion`), `fuzz`, `audio_bench`.
"""
