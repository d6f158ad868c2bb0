"""Print the error of an ``ndt-register`` result against the sample data's ground truth.

Usage: python tools/demo_check.py RESULT_DIR POSES_FILE TARGET_NAME SOURCE_NAME
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ndt_cli.transforms import read_matrix, read_pose_list, transform_errors, yaw_of


def main(argv: list[str]) -> int:
    result_dir, poses_file, target, source = argv
    T = read_matrix(Path(result_dir) / "T_target_source.txt")
    poses = read_pose_list(poses_file)
    T_ref = np.linalg.inv(poses[target]) @ poses[source]
    rot, trans = transform_errors(T, T_ref)
    print(f"ground truth: t = {np.round(T_ref[:3, 3], 4)} m, yaw = {np.degrees(yaw_of(T_ref)):.4f} deg")
    print(f"estimate:     t = {np.round(T[:3, 3], 4)} m, yaw = {np.degrees(yaw_of(T)):.4f} deg")
    print(f"error: rotation {rot:.4f} deg, translation {trans * 100:.2f} cm")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
