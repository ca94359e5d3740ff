"""Small stacks that several tests share."""

from __future__ import annotations

import numpy as np

import qpcoord as qc


def retry_leak_case() -> tuple[list, list, dict]:
    """``(head, extra, options)``: three levels over 5 variables with bounds and a hard
    inequality, a fourth level ``extra``, and the ``solve_stack`` options. Found by a
    property test on proxqp: a lower level leaked after a relaxed retry of a level QP; its
    level 0 (an inequality with lower == upper, zero targets) is met to rounding. Fresh
    tasks on every call."""
    head = [
        [
            qc.Inequality(
                [[-0.29, 1.74, 0.03, 0.67, 0.31], [-0.43, -0.82, 1.76, -1.47, -1.37]],
                [-1.35, -0.33],
                [-1.35, -0.33],
            )
        ],
        [
            qc.Equality(
                [
                    [-1.07, -0.82, 1.48, 1.21, -0.16],
                    [-0.77, 1.76, 0.76, -2.0, 0.94],
                    [1.6, -1.43, -0.63, 0.34, -0.13],
                ],
                [0.96, -2.06, -1.04],
            )
        ],
        [qc.Equality([[-0.77, -0.62, -0.15, 1.15, -1.75]], [-2.48])],
    ]
    extra = [
        qc.Equality(
            [[0.84, 0.57, -0.77, 1.39, 0.15], [1.58, 1.38, -0.77, 0.28, 1.52]],
            [-1.62, 0.12],
            weight=[1.0, 4.0],
        ),
        qc.Inequality(
            [
                [0.99, -1.12, 0.53, -1.14, -1.33],
                [0.54, 1.95, 0.09, -1.61, -1.53],
                [0.0, -1.36, 0.62, -1.92, -0.36],
            ],
            [-1.07, 2.64, -0.03],
            weight=[0.5, 2.0, 1.0],
        ),
    ]
    options = dict(
        bounds=qc.Bounds(
            [-np.inf, -1.66, -np.inf, -0.83, -1.63], [np.inf, 2.27, 1.89, np.inf, np.inf]
        ),
        constraints=[qc.Inequality([[-1.55, 1.1, 0.07, 0.2, 0.08]], [-1.49], [0.98])],
    )
    return head, extra, options
