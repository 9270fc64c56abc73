"""Writes ``scenario_pins.npz``: what the older scenarios produce (seed 0, 40 steps, shrink 4).

The pins replace float hashes, which fix one CPU's rounding of trigonometry rather than the scenario. They hold
the small arrays whole (ground truth, odometry, camera pose, heat-map flags) and the heat maps as row and
column sums for every step plus three whole maps (float16); ``tests/sim/test_scenarios.py`` compares them
with tolerances far above float32 noise and far below any change of the scenario. Regenerate only for an
intended change of a scenario: ``python -m tests.data.scenario_pins``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

PATH = Path(__file__).with_name("scenario_pins.npz")
OLDER = ("standard", "false_positives", "split", "far", "occlusion", "walking", "sparse_rate")
NUM_STEPS, SHRINK, SEED = 40, 4, 0
WHOLE_MAPS = (0, 20, 39)


def pins(seq) -> dict[str, np.ndarray]:
    """The pinned summary of one sequence."""
    heat = np.asarray(seq.heatmaps, np.float64)
    return {
        "ground_truth": np.asarray(seq.ground_truth),
        "odometry": np.asarray(seq.odometry),
        "cam_to_base": np.asarray(seq.cam_to_base),
        "has_heatmap": np.asarray(seq.has_heatmap),
        "row_sums": heat.sum(axis=2).astype(np.float32),
        "col_sums": heat.sum(axis=1).astype(np.float32),
        "maps": np.asarray(seq.heatmaps)[list(WHOLE_MAPS)].astype(np.float16),
    }


def main() -> None:
    from heatpf_jax.sim import simulate_with_info

    arrays = {}
    for name in OLDER:
        seq, _ = simulate_with_info(name, SEED, num_steps=NUM_STEPS, shrink=SHRINK)
        arrays.update({f"{name}/{key}": value for key, value in pins(seq).items()})
    np.savez_compressed(PATH, **arrays)
    print(f"wrote {PATH} ({PATH.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
