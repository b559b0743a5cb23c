"""Run every benchmark: trackers (semwm vs Stone Soup vs FilterPy) and scaling.

    python benchmarks/run_all.py [--quick]

Results go to ``benchmarks/results/`` (``*_quick.*`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_scaling
import bench_trackers


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="short runs (a few minutes)")
    args = parser.parse_args(argv)
    flags = ["--quick"] if args.quick else []
    bench_trackers.main(flags)
    bench_scaling.main(flags)


if __name__ == "__main__":
    main()
