"""Run every benchmark: trackers (semwm vs Stone Soup vs FilterPy) and scaling.

    python benchmarks/run_all.py [--quick] [--update-results]

Results go to ``benchmarks/out/`` (untracked; ``*_quick.*`` with ``--quick``). With
``--update-results`` they replace the committed ``benchmarks/results/`` and
benchmarks/README.md's tables are re-rendered from them (``benchmarks/render_tables.py``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_scaling
import bench_trackers
from baselines import add_output_arguments


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="short runs (a few minutes)")
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    flags = ["--quick"] if args.quick else []
    flags += ["--update-results"] if args.update_results else []
    bench_trackers.main(flags)
    bench_scaling.main(flags)


if __name__ == "__main__":
    main()
