"""Evaluation of the whole system as the wearer lives with it (outside core/).

* `safety`: the safety score of docs/evaluation.md (warned in time, false alarm
  events per minute of walking, false reports per frame, recall), one implementation
  used by `asmonc run`, `asmonc eval` and `asmonc campaign`.
* `truth`: the world's true obstacles with their footprints, from a simulated scene or
  from a bag's ground-truth topics.
* `alarm_replay`: the alarm node's logic driven over a detector's outputs in bag time.
"""
