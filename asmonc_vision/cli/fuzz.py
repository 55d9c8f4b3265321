"""Fuzz a parser of outside data for a given time: the NMEA attitude parser (what a
serial compass sends) or the bag reader (a damaged or hostile bag file).

    asmonc fuzz nmea --seconds 600
    asmonc fuzz bag --seconds 600 [--engine hypothesis]

With atheris installed (coverage-guided, libFuzzer) it is the engine; otherwise, or
with ``--engine hypothesis``, hypothesis generates and mutates inputs for the time
given. An input may only end in the documented errors (`NmeaError`; `BagError`); any
other exception is a crash: its input is written to ``--crash-dir`` and the command
exits with status 1. Prints the inputs run and their rate.
"""
from __future__ import annotations

from pathlib import Path

from asmonc_vision.eval.fuzz import TARGETS


def add_arguments(p) -> None:
    p.add_argument('target', choices=TARGETS, help='what to fuzz')
    p.add_argument('--seconds', type=float, default=60.0, help='how long (default 60)')
    p.add_argument('--engine', choices=('auto', 'atheris', 'hypothesis'), default='auto',
                   help='auto: atheris if installed, else hypothesis')
    p.add_argument('--crash-dir', type=Path, default=Path('.'),
                   help='where a crashing input is written (default: here)')
    p.add_argument('--seed', type=int, default=0, help='random seed (hypothesis engine)')
    p.set_defaults(func=run)


def run(args) -> int:
    from asmonc_vision.eval.fuzz import fuzz_command
    return fuzz_command(args)
