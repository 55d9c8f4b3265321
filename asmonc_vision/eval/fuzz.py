"""Fuzzing the NMEA parser and the bag reader (`asmonc fuzz`): the targets (one input
each; documented errors pass), their seed inputs, and the atheris or hypothesis engines.
The command's help (`cli.fuzz`) says more.
"""
from __future__ import annotations

import math
import os
import sys
import tempfile
import time
from pathlib import Path

TARGETS = ('nmea', 'bag')


# --- the targets: one input (bytes) each; documented errors pass --------------------------

class _Counter:
    def __init__(self) -> None:
        self.inputs = 0
        self.accepted = 0


def nmea_target(data: bytes, counter: _Counter | None = None) -> None:
    """Feed ``data`` through the line splitter and parse each line (and the whole input
    as one line); check what is accepted."""
    from asmonc_vision.core.nmea import LineSplitter, NmeaError, parse_sentence

    lines = LineSplitter().feed(data) + [data.decode('latin-1')]
    for line in lines:
        for strict in (True, False):
            try:
                a = parse_sentence(line, require_checksum=strict)
            except NmeaError as exc:
                if exc.reason not in ('checksum', 'format', 'unknown'):
                    raise AssertionError(f'NmeaError with reason {exc.reason!r}') from exc
                continue
            if not (math.isfinite(a.pitch_deg) and math.isfinite(a.roll_deg)
                    and (a.heading_deg is None or math.isfinite(a.heading_deg))):
                raise AssertionError(f'non-finite reading accepted from {line!r}: {a}')
            if counter is not None:
                counter.accepted += 1
    if counter is not None:
        counter.inputs += 1


def bag_target(data: bytes, workdir: Path, counter: _Counter | None = None) -> None:
    """Write ``data`` as an .mcap file and read it as `asmonc run` and the player do."""
    from asmonc_vision.io import bagio, bagplay

    path = workdir / 'input.mcap'
    path.write_bytes(data)
    errors = (bagio.BagError, bagplay.BagError)
    try:
        topics, _ = bagio.bag_summary(path)
        for _ in bagio.read_messages(path, list(topics)):
            pass
    except errors:
        pass
    try:
        src = bagplay.BagSource(path)
        for _ in src.messages():
            pass
        if counter is not None:
            counter.accepted += 1
    except errors:
        pass
    if counter is not None:
        counter.inputs += 1


def seed_inputs(target: str, workdir: Path) -> list[bytes]:
    """Valid inputs to start from: sentences of both kinds; a small bag (uncompressed
    and zstd-chunked) with images, camera_infos and inclinometer readings."""
    if target == 'nmea':
        from asmonc_vision.core.nmea import format_ptnthpr, format_tcm
        return [format_ptnthpr(123.4, -5.5, 2.0).encode(), format_tcm(10.0, 3.25, -1.5).encode(),
                (format_ptnthpr(0.0, 0.0, 0.0, status='NNO') + format_tcm(359.9, 89.0, -179.0,
                                                                           error='M')).encode()]
    return [small_bag(workdir / 'seed_plain', None), small_bag(workdir / 'seed_zstd', 'zstd')]


def small_bag(path: Path, compression: str | None) -> bytes:
    """The bytes of a tiny MCAP bag: 3 stereo pairs of 8x4 images with camera_infos and
    5 inclinometer readings (rosbags writer)."""
    import numpy as np
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    from asmonc_vision.io import bagio

    store = bagio.typestore()
    T = store.types
    stamp = lambda ns: T['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9)  # noqa: E731
    header = lambda ns, f: T['std_msgs/msg/Header'](stamp=stamp(ns), frame_id=f)  # noqa: E731
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    if compression:
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer as w:
        conns = {t: w.add_connection(t, typ, typestore=store) for t, typ in (
            ('/stereo/left/image_rect', 'sensor_msgs/msg/Image'),
            ('/stereo/right/image_rect', 'sensor_msgs/msg/Image'),
            ('/stereo/left/camera_info', 'sensor_msgs/msg/CameraInfo'),
            ('/inclinometer/imu', 'sensor_msgs/msg/Imu'))}
        for k in range(5):
            ns = 10**18 + k * 50_000_000
            imu = T['sensor_msgs/msg/Imu'](
                header=header(ns, 'inclinometer_link'),
                orientation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.1, z=0.0, w=0.995),
                orientation_covariance=np.eye(3).ravel() * 1e-4,
                angular_velocity=T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0),
                angular_velocity_covariance=np.r_[-1.0, np.zeros(8)],
                linear_acceleration=T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0),
                linear_acceleration_covariance=np.r_[-1.0, np.zeros(8)])
            w.write(conns['/inclinometer/imu'], ns,
                    store.serialize_cdr(imu, 'sensor_msgs/msg/Imu'))
            if k % 2:
                continue
            for side in ('left', 'right'):
                img = T['sensor_msgs/msg/Image'](
                    header=header(ns, f'stereo_{side}_optical_frame'), height=4, width=8,
                    encoding='mono8', is_bigendian=0, step=8,
                    data=np.arange(32, dtype=np.uint8) * (k + 1))
                w.write(conns[f'/stereo/{side}/image_rect'], ns,
                        store.serialize_cdr(img, 'sensor_msgs/msg/Image'))
            roi = T['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0,
                                                       width=0, do_rectify=False)
            info = T['sensor_msgs/msg/CameraInfo'](
                header=header(ns, 'stereo_left_optical_frame'), height=4, width=8,
                distortion_model='plumb_bob', d=np.zeros(5), k=np.eye(3).ravel(),
                r=np.eye(3).ravel(), p=np.array([100.0, 0, 4, 0, 0, 100, 2, 0, 0, 0, 1, 0]),
                binning_x=0, binning_y=0, roi=roi)
            w.write(conns['/stereo/left/camera_info'], ns,
                    store.serialize_cdr(info, 'sensor_msgs/msg/CameraInfo'))
    return next(path.glob('*.mcap')).read_bytes()


# --- engines ------------------------------------------------------------------------------------

def _one(target: str, workdir: Path, counter: _Counter):
    if target == 'nmea':
        return lambda data: nmea_target(data, counter)
    return lambda data: bag_target(data, workdir, counter)


def _run_atheris(target: str, seconds: float, workdir: Path, crash_dir: Path) -> int:
    import atheris

    corpus = workdir / 'corpus'
    corpus.mkdir()
    seeds = seed_inputs(target, workdir)
    for i, s in enumerate(seeds):
        (corpus / f'seed{i}').write_bytes(s)
    counter = _Counter()
    one = _one(target, workdir, counter)
    atheris.instrument_all()
    crash_dir.mkdir(parents=True, exist_ok=True)
    max_len = 256 if target == 'nmea' else max(len(s) for s in seeds) * 2
    argv = [sys.argv[0], str(corpus), f'-max_total_time={max(1, int(seconds))}',
            f'-max_len={max_len}', f'-artifact_prefix={crash_dir}/fuzz-{target}-',
            '-print_final_stats=1']
    print(f'asmonc fuzz {target} (atheris, coverage-guided) for {seconds:g} s: libFuzzer '
          "prints its progress; 'Done N runs' at the end means no crash", flush=True)
    atheris.Setup(argv, one)
    atheris.Fuzz()
    return 0


def _run_hypothesis(target: str, seconds: float, workdir: Path, crash_dir: Path,
                    seed: int) -> int:
    from hypothesis import HealthCheck, given, seed as hseed, settings
    from hypothesis import strategies as st

    seeds = seed_inputs(target, workdir)
    counter = _Counter()
    one = _one(target, workdir, counter)

    @st.composite
    def mutated(draw):
        data = bytearray(draw(st.sampled_from(seeds)))
        for _ in range(draw(st.integers(0, 8))):
            op = draw(st.sampled_from(('flip', 'cut', 'insert', 'zero')))
            if not data:
                break
            i = draw(st.integers(0, len(data) - 1))
            if op == 'flip':
                data[i] ^= 1 << draw(st.integers(0, 7))
            elif op == 'cut':
                del data[i:]
            elif op == 'insert':
                data[i:i] = draw(st.binary(min_size=1, max_size=16))
            else:
                data[i:i + draw(st.integers(1, 64))] = b'\0' * 8
        return bytes(data)

    inputs = mutated() | st.binary(max_size=300)
    deadline = time.monotonic() + seconds
    start, rounds = time.monotonic(), 0
    while time.monotonic() < deadline:
        @hseed(seed + rounds)
        @settings(max_examples=200, deadline=None, database=None,
                  report_multiple_bugs=False,
                  suppress_health_check=list(HealthCheck))
        @given(inputs)
        def check(data):
            try:
                one(data)
            except Exception:
                crash_dir.mkdir(parents=True, exist_ok=True)
                (crash_dir / f'fuzz-{target}-crash').write_bytes(data)
                raise
        try:
            check()
        except Exception as exc:  # noqa: BLE001 - report the crash and its input
            print(f'asmonc fuzz {target}: CRASH after {counter.inputs} inputs: '
                  f'{type(exc).__name__}: {exc}; input in {crash_dir}/fuzz-{target}-crash',
                  file=sys.stderr)
            return 1
        rounds += 1
    dt = time.monotonic() - start
    print(f'asmonc fuzz {target} (hypothesis): {counter.inputs} inputs in {dt:.0f} s '
          f'({counter.inputs / max(dt, 1e-9):.0f}/s), {counter.accepted} accepted, no crash')
    return 0


def fuzz_command(args) -> int:
    """`asmonc fuzz` with its parsed arguments (see `cli.fuzz`); the exit
    status."""
    if not args.seconds > 0:
        print('asmonc fuzz: --seconds must be > 0', file=sys.stderr)
        return 2
    engine = args.engine
    if engine == 'auto':
        try:
            import atheris  # noqa: F401
            engine = 'atheris'
        except ImportError:
            engine = 'hypothesis'
    with tempfile.TemporaryDirectory(prefix='asmonc-fuzz-') as tmp:
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        if engine == 'atheris':
            return _run_atheris(args.target, args.seconds, Path(tmp), args.crash_dir)
        return _run_hypothesis(args.target, args.seconds, Path(tmp), args.crash_dir,
                               args.seed)
