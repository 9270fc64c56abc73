"""``heatpf import-rosbag``: a ROS bag resampled onto a fixed filter clock and written as a version-1 sequence file.

The reading and resampling is :func:`heatpf_jax.io.rosbag_import.import_rosbag` (heat maps, camera info, tf,
odometry and optional ground truth; the rules are in that module's docstring); this module checks the output
(replaced only with ``--force``, never the bag), saves the sequence and prints one line about it. It needs the
``rosbags`` package (``pip install 'heatpf-jax[ros]'``).
"""

from __future__ import annotations

import argparse

from heatpf_jax.io.files import check_output

__all__ = ["add_parser", "cmd_import_rosbag"]


def cmd_import_rosbag(args: argparse.Namespace) -> int:
    """Runs ``heatpf import-rosbag`` on the parsed ``args``; returns the exit code (0)."""
    from heatpf_jax.io.rosbag_import import import_rosbag
    from heatpf_jax.io.sequence import save_sequence

    out = check_output("--output", args.output, inputs=(args.bag,), replace=args.force)
    seq = import_rosbag(
        args.bag,
        heatmap_topic=args.heatmap_topic,
        camera_info_topic=args.camera_info_topic,
        odom_topic=args.odom_topic,
        base_frame=args.base_frame,
        camera_frame=args.camera_frame,
        rate=args.rate,
        ball_radius=args.ball_radius,
        ground_truth_topic=args.ground_truth_topic,
    )
    save_sequence(out, seq)
    h, w = seq.heatmaps.shape[1:]
    print(
        f"import-rosbag: {seq.num_steps} steps at {args.rate:g} Hz, {int(seq.has_heatmap.sum())} with a "
        f"{w} x {h} heat map, {'with' if seq.ground_truth is not None else 'no'} ground truth -> {out}"
    )
    return 0


def add_parser(sub, parents: list[argparse.ArgumentParser] = ()) -> argparse.ArgumentParser:
    """Registers ``import-rosbag`` on ``sub`` (an ``argparse`` sub-parser collection) with the ``parents`` parsers;
    returns its parser.

    The parser's default ``func`` (:func:`cmd_import_rosbag`) takes the parsed ``args`` and returns the exit code;
    bad input raises :class:`ValueError` (:class:`~heatpf_jax.io.sequence.SequenceError` included) with one line.
    """
    p = sub.add_parser(
        "import-rosbag",
        parents=list(parents),
        help="convert a ROS bag (rosbag2 sqlite3/mcap, or ROS 1) into a version-1 sequence file",
        description="Resample heat maps, camera info, tf, odometry and optional ground truth from a ROS bag onto "
        "a fixed filter clock and write a version-1 sequence (.npz). Needs the 'rosbags' package "
        "(pip install 'heatpf-jax[ros]').",
    )
    p.add_argument("bag", help="rosbag2 directory (sqlite3 or mcap storage) or ROS 1 .bag file")
    p.add_argument("--heatmap-topic", required=True, help="sensor_msgs/Image heat maps (mono8, 8UC1 or 32FC1)")
    p.add_argument("--camera-info-topic", required=True, help="sensor_msgs/CameraInfo of the heat maps' camera")
    p.add_argument("--odom-topic", required=True, help="nav_msgs/Odometry of the robot")
    p.add_argument("--base-frame", default="base_footprint", help="robot base frame (default base_footprint)")
    p.add_argument("--camera-frame", help="camera optical frame in tf (default: the heat maps' header.frame_id)")
    p.add_argument("--rate", type=float, default=10.0, help="filter rate in Hz (default 10)")
    p.add_argument("--ball-radius", type=float, default=0.07, help="ball radius in metres (default 0.07)")
    p.add_argument("--ground-truth-topic", help="optional geometry_msgs PointStamped or PoseWithCovarianceStamped")
    p.add_argument("--output", "-o", required=True, help="sequence file to write (.npz)")
    p.add_argument("--force", action="store_true", help="replace an existing output file")
    p.set_defaults(func=cmd_import_rosbag)
    return p
