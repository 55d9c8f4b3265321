"""Benchmark of what the wearer hears: latency from a stereo pair to its sound, and the
soundtrack's counts, over `asmonc run --audio` replays of bags at rate 1.

    python -m asmonc_vision.eval.audio_bench [BAG ...] [--out DIR] [--rate R] [--cpus LIST]
        [--params-file YAML ...] [--record]

For each bag (default: every bundled bag) it runs `asmonc run BAG --audio DIR/<bag>.wav`
in a subprocess (recording nothing, as the live graph; ``--record`` adds the
recorder), then prints, from the audio node's ``.latency.json`` and
``.cues.json``: the pair-to-cue-onset latency (a pair's arrival at the audio node's
process -- for a live camera, its stamp -- to the onset of the cue it decided, plus the
device's output latency), the pair-to-contact latency (to the arrival of that pair's
/alarms/contact, when a cue for any pair could start), p50 and p99; the cues and
phrases given, the shortest gap between two phrases, and the FAULTs other than
"starting up". ``--cpus 0`` runs each replay, every node of it, on CPU 0 alone (Linux
``taskset``): the latency on one core. A benchmark prints numbers; it asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

BAGS = Path(__file__).resolve().parents[2] / 'bags'


def _pct(x, q):
    return f'{np.percentile(x, q) * 1e3:6.1f}' if len(x) else '     -'


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('bags', nargs='*', type=Path)
    p.add_argument('--out', type=Path, default=None, help='keep the WAVs etc. here')
    p.add_argument('--rate', type=float, default=1.0)
    p.add_argument('--params-file', type=Path, action='append', default=[],
                   help='a ros__parameters YAML passed to the nodes (repeatable)')
    p.add_argument('--warmup', type=float, default=1.0,
                   help='also print the latencies of the pairs from this many seconds after '
                        'the first one (the graph\'s start-up left out), s (default 1)')
    p.add_argument('--record', action='store_true',
                   help='also record every output topic (asmonc run --out): the recorder '
                        'is no part of the live graph, and its CPU is counted then')
    p.add_argument('--cpus', default=None,
                   help='run each replay on these CPUs only (taskset list, e.g. 0)')
    args = p.parse_args(argv)
    pin = ['taskset', '-c', args.cpus] if args.cpus else []
    print(f'load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; replays '
          + (f'on CPU(s) {args.cpus} only' if pin else 'on every core'))
    bags = args.bags or sorted(d for d in BAGS.iterdir() if (d / 'metadata.yaml').exists())
    out = args.out or Path(tempfile.mkdtemp(prefix='asmonc-audio-bench-'))
    out.mkdir(parents=True, exist_ok=True)
    all_cue, all_contact, all_det, all_alarm = [], [], [], []
    warm_cue, warm_contact = [], []
    print(f'{"bag":18s} {"cues":>4s} {"phr":>3s} {"min phrase gap":>14s} {"FAULTs":>6s}  '
          f'{"cue p50/p99 ms":>15s}  {"contact p50/p99 ms":>18s}')
    for bag in bags:
        wav = out / f'{bag.name}.wav'
        res = subprocess.run([*pin, sys.executable, '-m', 'asmonc_vision.cli.main', 'run',
                              str(bag), '--audio', str(wav), '--rate', str(args.rate), '--quiet',
                              '--no-progress',
                              *(['--out', str(out / bag.name)] if args.record else []),
                              *[a for f in args.params_file for a in ('--params-file', str(f))]],
                             capture_output=True, text=True)
        if res.returncode != 0 or not wav.exists():
            print(f'{bag.name:18s} run failed (exit {res.returncode}): '
                  f'{res.stderr.strip().splitlines()[-1:] }')
            continue
        lat = json.loads(wav.with_suffix('.latency.json').read_text())
        cues = json.loads(wav.with_suffix('.cues.json').read_text())
        faults = [a for a in cues['alarms']
                  if a['level'] == 4 and not a['text'].startswith('starting')]
        phrases = [e['t'] for e in cues['events'] if e['what'].startswith('phrase')]
        n_cues = sum(1 for e in cues['events'] if not e['what'].startswith('phrase'))
        gap = f'{np.diff(sorted(phrases)).min():.2f} s' if len(phrases) > 1 else '-'
        for vals, times, into in ((lat['latency_s'], lat.get('latency_t_s'), warm_cue),
                                  (lat.get('contact_latency_s', []), lat.get('contact_t_s'),
                                   warm_contact)):
            if times is not None:
                into += [v for v, t in zip(vals, times) if t >= args.warmup]
        all_cue += lat['latency_s']
        all_contact += lat.get('contact_latency_s', [])
        all_det += lat.get('detector_latency_s', [])
        all_alarm += lat.get('alarm_latency_s', [])
        print(f'{bag.name:18s} {n_cues:4d} {len(phrases):3d} {gap:>14s} {len(faults):6d}  '
              f'{_pct(lat["latency_s"], 50)}/{_pct(lat["latency_s"], 99)}  '
              f'{_pct(lat.get("contact_latency_s", []), 50):>11s}/'
              f'{_pct(lat.get("contact_latency_s", []), 99)}')
    print(f'{"all":18s} {"":4s} {"":3s} {"":14s} {"":6s}  {_pct(all_cue, 50)}/{_pct(all_cue, 99)}'
          f'  {_pct(all_contact, 50):>11s}/{_pct(all_contact, 99)}   '
          f'({len(all_cue)} cues, {len(all_contact)} pairs)')
    print(f'{"from " + format(args.warmup, "g") + " s on":18s} {"":4s} {"":3s} {"":14s} {"":6s}  '
          f'{_pct(warm_cue, 50)}/{_pct(warm_cue, 99)}  {_pct(warm_contact, 50):>11s}/'
          f'{_pct(warm_contact, 99)}   ({len(warm_cue)} cues, {len(warm_contact)} pairs)')
    print(f'pair -> contact split, p50/p99 ms: pair -> its /obstacles (detector, egomotion) '
          f'{_pct(all_det, 50).strip()}/{_pct(all_det, 99).strip()}; /obstacles -> '
          f'/alarms/contact (alarm node) {_pct(all_alarm, 50).strip()}/'
          f'{_pct(all_alarm, 99).strip()}')
    print(f'outputs in {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
