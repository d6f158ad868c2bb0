"""Print the error of an ndt-register result against the sample data's ground truth.

Usage: python tools/demo_check.py pair RESULT_DIR POSES_FILE TARGET_NAME SOURCE_NAME
(chains are evaluated by ``ndt-eval``)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ndt_cli.core.transforms import transform_errors, yaw_of
from ndt_cli.io.matrices import read_matrix, read_pose_list


def _line(label: str, T: np.ndarray, T_ref: np.ndarray) -> str:
    rot, trans = transform_errors(T, T_ref)
    return (
        f"{label:<28} t = ({T[0, 3]:8.3f}, {T[1, 3]:8.3f}, {T[2, 3]:6.3f}) m  "
        f"yaw = {np.degrees(yaw_of(T)):8.3f} deg   error: {rot:.4f} deg, {trans * 100:.2f} cm"
    )


def pair(result_dir: str, poses_file: str, target: str, source: str) -> int:
    T = read_matrix(Path(result_dir) / "T_target_source.txt")
    poses = read_pose_list(poses_file)
    T_ref = np.linalg.inv(poses[target]) @ poses[source]
    print(_line("ground truth", T_ref, T_ref))
    print(_line(f"{source} -> {target}", T, T_ref))
    return 0


if __name__ == "__main__":
    sys.exit(pair(*sys.argv[2:]))
