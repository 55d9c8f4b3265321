"""Settings of the alarm logic (`core.alarm`): the alarm node's ROS parameters.

What each setting does is told in `core.alarm`'s module docstring; ranges are in metres
along the ground, times in seconds on the caller's clock. ``config/alarm.yaml`` holds the
same values in ``ros__parameters`` form (tested).
"""
from __future__ import annotations

from dataclasses import dataclass

from asmonc_vision.core.config import check_fields, param


@dataclass(frozen=True)
class AlarmConfig:
    """Settings of the alarm logic (ROS parameters of the alarm node)."""

    corridor_half_width: float = param(
        0.5, 'half width of the walking corridor, metres: obstacles whose lateral offset '
        '|range*sin(bearing)| is larger are ignored', range=(0.05, 5.0))
    max_range: float = param(
        5.0, 'obstacles farther than this along the ground are ignored, metres',
        range=(0.5, 50.0))
    stop_range: float = param(
        1.2, 'STOP when the nearest obstacle in the corridor is this near or nearer, metres',
        range=(0.1, 20.0))
    warning_range: float = param(
        2.5, 'WARNING when the nearest obstacle is this near or nearer, metres',
        range=(0.1, 30.0))
    caution_range: float = param(
        5.0, 'CAUTION when the nearest obstacle is this near or nearer, metres '
        '(must not exceed max_range)', range=(0.1, 50.0))
    hysteresis: float = param(
        0.3, 'a level already held is kept until the range exceeds its threshold by this '
        'much, metres', range=(0.0, 5.0))
    hold_time: float = param(
        1.0, 'a lower level must persist this long before the alarm steps down, seconds '
        '(going up is always immediate)', range=(0.0, 30.0))
    min_height: float = param(
        0.05, 'obstacles lower than this are ignored, metres; drops (negative height) '
        'deeper than this alarm too', range=(0.0, 2.0))
    min_confidence: float = param(
        0.3, 'obstacles with a lower detector confidence are ignored (0..1)',
        range=(0.0, 1.0))
    timeout: float = param(
        0.4, 'FAULT when no obstacle list has arrived for this long, or the ground plane '
        'has been LOST this long, seconds (with the node\'s 0.05 s check and the transport: '
        'FAULT heard within 0.5 s of perception stopping)', range=(0.05, 60.0))
    startup_grace: float = param(
        10.0, 'at start (or while the ground plane initialises) FAULT says "starting up" '
        'for at most this long before it says the system has stopped, seconds',
        range=(0.0, 300.0))
    repeat_period: float = param(
        2.0, 'a non-clear alarm (including FAULT) is announced again this often, seconds',
        range=(0.2, 60.0))
    ahead_angle_deg: float = param(
        10.0, 'bearings within +-this angle are spoken as "ahead", degrees',
        range=(0.0, 90.0))
    side_angle_deg: float = param(
        30.0, 'bearings within +-this angle (and beyond ahead_angle_deg) are spoken as '
        '"slightly left/right"; beyond as "left/right", degrees', range=(0.0, 90.0))
    stop_time: float = param(
        1.5, 'while walking, STOP when the time to contact (distance along the walking '
        'direction / walking speed) is this short or shorter, seconds', range=(0.1, 20.0))
    warning_time: float = param(
        3.0, 'while walking, WARNING at this time to contact or less: the lead time, '
        'seconds', range=(0.1, 30.0))
    caution_time: float = param(
        5.0, 'while walking, CAUTION at this time to contact or less, seconds',
        range=(0.1, 60.0))
    time_hysteresis: float = param(
        0.5, 'a level already held is kept until the time to contact exceeds its time by '
        'this much, seconds', range=(0.0, 10.0))
    min_walking_speed: float = param(
        0.2, 'the wearer counts as moving at this walking speed or faster (and when the '
        'walk model, if any, says walking), m/s', range=(0.0, 3.0))
    motion_timeout: float = param(
        1.0, 'a walking speed or gait state older than this is not used (levels by range '
        'only), seconds', range=(0.05, 60.0))
    follow_walking_direction: bool = param(
        True, 'lay the walking corridor along the walking direction (from /egomotion) '
        'rather than the camera\'s axis while the wearer moves')
    max_heading_deg: float = param(
        45.0, 'a walking direction further than this from the camera\'s axis is clipped '
        'to it, degrees', range=(0.0, 90.0))
    repeat_when_standing: bool = param(
        False, 'repeat an unchanged alarm every repeat_period also while the wearer stands '
        'still (false: a standing wearer hears a known obstacle once)')
    lost_hold: float = param(
        2.0, 'while the ground plane is LOST, a hazard announced at CAUTION or higher and '
        'last seen at most this long ago, carried by the distance walked since and not yet '
        'reached, keeps its level (rising as it comes nearer) in place of FAULT '
        '"cannot see the ground", seconds; 0: FAULT after timeout whatever was announced',
        range=(0.0, 30.0))
    require_ground_plane: bool = param(
        True, 'until the detector has reported a TRACKING ground plane on /ground_plane, '
        'obstacle lists count as "starting up": an empty list before the ground is seen is '
        'no evidence of a clear path. False only for detectors that publish no /ground_plane')

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.stop_range < self.warning_range:
            raise ValueError(f'AlarmConfig.stop_range = {self.stop_range} must be less than '
                             f'warning_range = {self.warning_range} (metres)')
        if not self.warning_range <= self.caution_range:
            raise ValueError(f'AlarmConfig.warning_range = {self.warning_range} must not '
                             f'exceed caution_range = {self.caution_range} (metres)')
        if not self.caution_range <= self.max_range:
            raise ValueError(f'AlarmConfig.caution_range = {self.caution_range} must not '
                             f'exceed max_range = {self.max_range} (metres)')
        if not self.stop_time < self.warning_time <= self.caution_time:
            raise ValueError(f'AlarmConfig: stop_time = {self.stop_time} < warning_time = '
                             f'{self.warning_time} <= caution_time = {self.caution_time} '
                             '(seconds) must hold')
        if not self.ahead_angle_deg <= self.side_angle_deg:
            raise ValueError(f'AlarmConfig.ahead_angle_deg = {self.ahead_angle_deg} must not '
                             f'exceed side_angle_deg = {self.side_angle_deg} (degrees)')
