"""bench_step.py on two commits, alternating runs, one table of medians: is a change slower?

    python benchmarks/ab_commits.py --base 4391092 [--head HEAD] [--runs 5] [-- BENCH_STEP_ARGS ...]

Each commit is checked out into a temporary git worktree (removed afterwards) and its own
``benchmarks/bench_step.py`` runs there with that commit's package first on ``PYTHONPATH``. The two
commits run alternately (base, head, base, head, ...) so that the machine's drift hits both alike.
Each row gives the median over runs of each run's median, its range, and head / base. On a shared
machine single runs vary by 20-30 %: read ratios within that spread as "no change".
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROW = re.compile(r"\s+(\d+)\s+(\d+)\s+(step, .*?\)|particle_weights k=10 \(blocked\))\s+([\d.]+)\s+([\d.]+)")


def _run(tree: Path, args: list[str]) -> dict[tuple[str, str, str], float]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run(
        [sys.executable, "benchmarks/bench_step.py", *args], cwd=tree, env=env, capture_output=True, text=True,
        check=True,
    ).stdout
    return {(m[1], m[2], m[3].strip()): float(m[4]) for m in map(ROW.match, out.splitlines()) if m}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="the commit to compare against")
    parser.add_argument("--head", default="HEAD", help="the commit measured (default HEAD)")
    parser.add_argument("--runs", type=int, default=5, help="runs of each commit (default 5)")
    parser.add_argument("bench_args", nargs="*", help="arguments for bench_step.py (after --)")
    args = parser.parse_args()
    repo = Path(subprocess.run(["git", "rev-parse", "--show-toplevel"], capture_output=True, text=True,
                               check=True).stdout.strip())
    results: dict[str, list[dict]] = {"base": [], "head": []}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {}
        for name in ("base", "head"):
            rev = getattr(args, name)
            trees[name] = Path(tmp) / name
            subprocess.run(["git", "worktree", "add", "--detach", str(trees[name]), rev], cwd=repo, check=True,
                           capture_output=True)
        try:
            for i in range(args.runs):
                for name in ("base", "head"):
                    print(f"run {i + 1}/{args.runs}: {name}", file=sys.stderr)
                    results[name].append(_run(trees[name], args.bench_args))
        finally:
            for tree in trees.values():
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=repo, capture_output=True)
    print(f"bench_step.py {' '.join(args.bench_args)}: base {args.base}, head {args.head}, {args.runs} runs each, "
          "alternating; ms, median of run medians (range)")
    print(f"{'P x M':>11}  {'row':<36} {'base':>22} {'head':>22} {'head/base':>9}")
    for key in results["base"][0]:
        base = [r[key] for r in results["base"] if key in r]
        head = [r[key] for r in results["head"] if key in r]
        if not head:
            continue
        mb, mh = statistics.median(base), statistics.median(head)
        print(f"{key[0] + ' x ' + key[1]:>11}  {key[2]:<36} {mb:8.3f} ({min(base):.3f}-{max(base):.3f})"
              f" {mh:8.3f} ({min(head):.3f}-{max(head):.3f}) {mh / mb:9.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
