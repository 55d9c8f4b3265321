"""What a replay found: the bag's ground truth, the summary, its score and its print-out."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

from asmonc_vision.eval.evaluation import (FrameObstacles, path_criteria, path_warnings,
                                           path_warnings_summary, score_sequence)
from asmonc_vision.io import bagio
from asmonc_vision.io.frames import frame_from_obstacle_array
from asmonc_vision.replay.monitor import Console, Monitor
from asmonc_vision.replay.params import LEVEL_NAMES, alarm_config, default_bag


def read_truth(bag: Path) -> dict[int, FrameObstacles]:
    """stamp_ns -> true obstacles, from /ground_truth/obstacles (empty if the bag has none).
    Of a truncated bag, the BagError carries those before the cut as ``partial``."""
    topic = bagio.TOPICS['gt_obstacles'][0]
    out: dict[int, FrameObstacles] = {}
    try:
        for _, _, m in bagio.read_messages(bag, [topic]):
            out[bagio.header_stamp_ns(m)] = frame_from_obstacle_array(m)
    except bagio.BagError as exc:
        exc.partial = out
        raise
    return out


def read_out_of_view_truth(bag: Path, truth: dict[int, FrameObstacles]
                           ) -> dict[int, FrameObstacles] | None:
    """stamp_ns -> true obstacles out of view (`eval.evaluation.out_of_view_truth`), from
    the bag's /ground_truth/camera_pose and /ground_truth/ground_plane; None when it has
    no poses."""
    from asmonc_vision.io.frames import plane_from_msg, pose_from_msg
    from asmonc_vision.eval.evaluation import out_of_view_truth

    t_pose, t_plane = bagio.TOPICS['gt_camera_pose'][0], bagio.TOPICS['gt_ground_plane'][0]
    poses, planes = {}, {}
    for topic, _, m in bagio.read_messages(bag, [t_pose, t_plane]):
        stamp = bagio.header_stamp_ns(m)
        if topic == t_pose:
            poses[stamp] = pose_from_msg(m)
        else:
            plane = plane_from_msg(m)
            if plane is not None:
                planes[stamp] = plane
    if not poses:
        return None
    return out_of_view_truth(truth, poses, planes)


def first_image_stamp(bag: Path) -> int | None:
    topic = bagio.TOPICS['left_image'][0]
    for _, _, m in bagio.read_messages(bag, [topic]):
        return bagio.header_stamp_ns(m)
    return None


def bag_time(stamp_ns: int, t0: int) -> str:
    """Seconds into the bag, or '(live)' for alarms stamped by a node's own clock
    (start-up, timeouts), which are not bag times."""
    t = (stamp_ns - t0) / 1e9
    return f'{t:7.1f} s' if t0 and -60.0 < t < 86400.0 else '   (live)'


def audio_outputs(args, monitor: 'Monitor', t0: int, truth: dict, bag: Path,
                   console: 'Console') -> dict:
    """After an --audio run: the PNG timeline, and the files written."""
    from asmonc_vision.replay.audio_timeline import write_timeline
    wav = args.audio.resolve()
    out = {'wav': str(wav), 'cues': str(wav.with_suffix('.cues.json')),
           'png': str(wav.with_suffix('.png'))}
    if not wav.exists():
        console.line(f'asmonc run: the audio node wrote no {wav}', err=True)
        return out
    with monitor.lock:
        alarms = list(monitor.alarms)
    write_timeline(wav.with_suffix('.png'), wav.with_suffix('.cues.json'), alarms, t0, truth,
                   alarm_config(args.params_file), title=f'{bag.name}: what the wearer heard')
    console.line(f'soundtrack: {wav} (timeline {wav.with_suffix(".png")})')
    return out


def summarise(monitor: Monitor, truth: dict, n_pairs: int, args,
              out_of_view: dict | None = None, safety_truth=None) -> dict:
    """Counts, alarms and the score against ground truth, as a JSON-ready dict.
    ``out_of_view``: stamp_ns -> true obstacles out of view (`read_out_of_view_truth`):
    reports of them are counted as remembered, not false. ``safety_truth``
    (`eval.truth.truth_from_bag`): the recorded /alarms and /obstacles get the safety
    score of EVALUATION.md (`eval.safety`), key ``safety``."""
    with monitor.lock:
        detections = dict(monitor.detections)
        alarms = list(monitor.alarms)
    levels = Counter(LEVEL_NAMES.get(a['level'], str(a['level'])) for a in alarms)
    out = {'bag': str(args.bag or default_bag()), 'rate': args.rate, 'input_pairs': n_pairs,
           'processed_frames': len(detections), 'dropped_frames': max(0, n_pairs - len(detections)),
           'alarms': dict(levels), 'alarm_log': alarms,
           'obstacle_reports': int(sum(len(d) for d in detections.values())),
           'gait_states': monitor.gait_states, 'gait_walking_states': monitor.gait_walking}
    if truth:
        score, missing = score_sequence(detections, truth, remembered=out_of_view,
                                        match_radius=args.match_radius,
                                        min_height=args.min_height, max_range=args.max_range)
        out['ground_truth'] = score.as_dict()
        out['ground_truth']['criteria'] = {'match_radius_m': args.match_radius,
                                           'min_height_m': args.min_height,
                                           'max_range_m': args.max_range}
        out['dropped_frames'] = max(out['dropped_frames'], len(missing))
        cfg = alarm_config(args.params_file)
        out['path_warnings'] = path_warnings_summary(
            path_warnings(truth, alarms, out_of_view, cfg), path_criteria(cfg))
    if safety_truth is not None:
        from asmonc_vision.eval.safety import score_safety
        out['safety'] = score_safety(safety_truth, alarms, detections).as_dict()
    return out


def path_warning_lines(pw: dict | None) -> list[str]:
    """The summary's lines on `eval.evaluation.path_warnings_summary` ``pw``: the counts,
    then each obstacle not warned in time or with unwarned frames (none if ``pw`` is
    None)."""
    if not pw:
        return []
    c = pw['criteria']
    lines = [f"obstacles on the path (within {c['corridor_half_width']:g} m of it, "
             f"{c['warning_range']:g} m ahead, >= {c['min_height'] * 100:.0f} cm): "
             f"{pw['on_path']}; warned in time {pw['warned_in_time']}, late "
             f"{pw['warned_late']}, never {pw['never_warned']}; frames on the path with no "
             f"warning {pw['frames_unwarned']}/{pw['frames_on_path']} "
             f"(FAULT in {pw['frames_fault']})"]
    for o in pw['obstacles']:
        if o['warned_in_time'] and not o['frames_unwarned']:
            continue
        warned = ('never warned' if o['warned_at_m'] is None
                  else f"warned at {o['warned_at_m']:.1f} m")
        lines.append(f"  obstacle {o['id']:>3}: {o['height_m'] * 100:5.1f} cm, on the path "
                     f"from {o['first_on_path_m']:.1f} m to {o['nearest_m']:.1f} m — {warned}, "
                     f"{o['frames_unwarned']}/{o['frames_on_path']} frames without a warning")
    return lines


def print_summary(s: dict, console: Console) -> None:
    p = lambda t: console.line(t, err=False) if not console.quiet else print(t)  # noqa: E731
    p('')
    p('=== summary ===')
    if s['input_pairs']:
        p(f"frames: {s['processed_frames']} of {s['input_pairs']} processed, "
          f"{s['dropped_frames']} dropped")
        rp = s.get('replay')
        if rp and rp['mode'] == 'paced' and rp['held_back_times']:
            p(f"replay held back {rp['held_back_times']} time(s), {rp['held_back_s']:.1f} s "
              'in all, while the detector was behind'
              + (f"; {rp['pairs_given_up']} pair(s) given no answer" if rp['pairs_given_up']
                 else ''))
    if s['gait_states']:
        p(f"walk model: {s['gait_states']} /gait/state messages, walking in "
          f"{s['gait_walking_states']}")
    alarms = ', '.join(f'{k} {v}' for k, v in sorted(s['alarms'].items())) or 'none'
    p(f'alarms given: {alarms}')
    gt = s.get('ground_truth')
    if gt:
        c = gt['criteria']
        p(f"true obstacles (>= {c['min_height_m'] * 100:.0f} cm high, within "
          f"{c['max_range_m']:g} m; found = a report within {c['match_radius_m']:g} m of it "
          'on the ground):')
        for oid, o in gt['obstacles'].items():
            if o['frames_eligible'] == 0:
                continue
            verdict = 'DETECTED' if o['detected'] else 'MISSED'
            p(f"  obstacle {oid:>3}: {o['height_m'] * 100:5.1f} cm, nearest "
              f"{o['min_range_m']:4.1f} m — {verdict} in "
              f"{o['frames_detected']}/{o['frames_eligible']} frames")
        recall = gt['recall']
        p(f"recall per frame: {gt['detected']}/{gt['eligible']}"
          + (f' = {recall:.1%}' if gt['eligible'] else ''))
        p(f"false obstacles: {gt['false_obstacles']} in {gt['frames']} frames "
          f"({gt['false_per_frame']:.3f} per frame); "
          f"{gt.get('remembered_out_of_view', 0)} more reports of true obstacles out of view "
          f"(remembered, not false)")
        if gt['range_error_median_m'] is not None:
            p(f"median |range error| {gt['range_error_median_m']:.3f} m, "
              f"median |bearing error| {gt['bearing_error_median_deg']:.2f} deg")
        for line in path_warning_lines(s.get('path_warnings')):
            p(line)
        if s.get('safety'):
            from asmonc_vision.eval.safety import format_safety
            p('safety (EVALUATION.md):')
            for line in format_safety(s['safety'], '  '):
                p(line)
    else:
        p('no ground truth in this bag: no score')
    f = s.get('faults')
    if f:
        p(f"faults injected: {'; '.join(f['spec'])}"
          + (f"; {f['affected_pairs']} pair(s) changed or left out, good pairs without a "
             f"result: {f['good_pairs_without_result']}" if 'affected_pairs' in f else ''))
    for e in s.get('errors', []):
        p(f'error: {e}')
