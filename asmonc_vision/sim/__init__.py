"""asmonc_vision.sim: a ray-cast stereo simulator of a wearer walking on a pavement.

Rectified mono8 stereo pairs of a textured world (tiled, asphalt or concrete pavement
with markings, boxes, posts, bollards, kerbs, drops, doors, walls, walking people, slopes,
crests, dips, kerb ramps) rendered by vectorised ray casting with
supersampling, a 6-DoF walking motion (Molton et al. 1998, Section 5), a 16 Hz
compass/inclinometer with phase lag, per-pixel and per-obstacle ground truth, and a
rosbag2 (MCAP, zstd) writer following ``bagio.TOPICS``.

Modules:
    rig           RigSettings (the paper's rig by default), frame ids.
    geometry      rotations, RigPose, CameraPose, camera_poses.
    texture       world-fixed value noise and box-filtered line patterns.
    world         Ground, PavementSettings, Box, Cylinder, Terrace, World and builders
                  (post, bollard, wall, door, kerb_up, step_down).
    relief        GroundProfile: slopes starting/ending ahead, crests, dips, ramps.
    surfaces      asphalt and concrete pavements; Marking (paint, zebra, grate,
                  manhole, stains, shadows).
    people        Person, walker: people walking along timed tracks.
    render        StereoRenderer -> StereoImages (images, depth, labels).
    motion        GaitSettings, Leg, Trajectory (walk plans with gait oscillations).
    inclinometer  InclinometerSettings, simulate_inclinometer.
    truth         ground_plane_truth, obstacle_truth, ObstacleTruth.
    scenarios     Scenario, SCENARIOS, make_scenario, simulate, simulate_frame.
    scenes        the campaign's scene classes: SCENE_CLASSES, RIGS, make_scene.
    benchmark     render time per frame of the scene classes.
    bagwriter     write_bag, EPOCH_NS.
    cli           main (``python -m asmonc_vision.sim``, ``asmonc-sim``).

Importing this package does not import rosbags (only ``bagwriter`` does).
"""
from asmonc_vision.sim.geometry import CameraPose, RigPose, camera_poses
from asmonc_vision.sim.inclinometer import InclinometerSettings, simulate_inclinometer
from asmonc_vision.sim.motion import GaitSettings, Leg, Trajectory
from asmonc_vision.sim.people import Person, walker
from asmonc_vision.sim.relief import GroundProfile
from asmonc_vision.sim.render import StereoImages, StereoRenderer
from asmonc_vision.sim.rig import (IMU_FRAME, LEFT_FRAME, RIGHT_FRAME, WORLD_FRAME,
                                   RigSettings)
from asmonc_vision.sim.scenarios import (DEFAULT_DURATIONS, SCENARIOS, Scenario, SimFrame,
                                         make_scenario, simulate, simulate_frame)
from asmonc_vision.sim.scenes import (CLEAR_CLASSES, EXTRA_CLASSES, RIGS, SCENE_CLASSES,
                                      make_scene)
from asmonc_vision.sim.surfaces import Marking
from asmonc_vision.sim.truth import ObstacleTruth, ground_plane_truth, obstacle_truth
from asmonc_vision.sim.world import (Box, Cylinder, Ground, Obstacle, PavementSettings,
                                     Terrace, World, bollard, door, kerb_up, post, step_down,
                                     wall)

__all__ = [
    'Box', 'CLEAR_CLASSES', 'CameraPose', 'Cylinder', 'EXTRA_CLASSES', 'GroundProfile',
    'Marking', 'Person', 'RIGS', 'SCENE_CLASSES', 'make_scene', 'walker', 'DEFAULT_DURATIONS',
    'GaitSettings', 'Ground',
    'IMU_FRAME', 'InclinometerSettings', 'LEFT_FRAME', 'Leg', 'Obstacle', 'ObstacleTruth',
    'PavementSettings', 'RIGHT_FRAME', 'RigPose', 'RigSettings', 'SCENARIOS', 'Scenario',
    'SimFrame', 'StereoImages', 'StereoRenderer', 'Terrace', 'Trajectory', 'WORLD_FRAME',
    'World', 'bollard', 'camera_poses', 'door', 'ground_plane_truth', 'kerb_up',
    'make_scenario', 'obstacle_truth', 'post', 'simulate', 'simulate_frame',
    'simulate_inclinometer', 'step_down', 'wall',
]
