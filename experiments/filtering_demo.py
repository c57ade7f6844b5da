"""The filtering demo (``python -m jbevo.demo``: a planar pose UKF learns its Q and R from pose
supervision) over several seeds; each seed simulates other training and validation drives.

    python experiments/filtering_demo.py [--seeds 0 1 2]

Writes ``experiments/results/filtering_demo.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from jbevo.cli import demo
from jbevo.files import write_json_atomic

RESULTS = Path(__file__).resolve().parent / "results"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    runs = {str(s): demo.demo(demo.build_parser().parse_args(["--seed", str(s)])) for s in args.seeds}
    write_json_atomic(args.out / "filtering_demo.json", {"command": "python -m jbevo.demo --seed S", "seeds": runs})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
