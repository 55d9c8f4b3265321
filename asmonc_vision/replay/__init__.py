"""Replaying a bag through the node graph (`asmonc run`), outside the command line.

* `session`: the replay itself -- checks, the nodes as processes, the wait for results.
* `children`: a node in its own process, the gait node's stopper, the fault schedule.
* `monitor`: the in-process subscriber of the results, and the console.
* `summary`: ground truth read from the bag, the summary and its score.
* `params`: the replay's defaults and the nodes' parameters it needs to know.
* `domain`: a ROS domain id per run, so that runs side by side do not mix.
"""
