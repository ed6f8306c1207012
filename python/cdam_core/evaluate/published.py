"""Published figures we compare against, in one place, with their sources.

NANODRONE_PUBLISHED: Busetto, Cereda, Forgione, Maroni, Piga, Palossi, "Nonlinear system
identification for a nano-drone benchmark", Control Engineering Practice 172 (2026) 106871
(arXiv 2512.14450; code and weights: github.com/idsia-robotics/nanodrone-sysid-benchmark), as
quoted in this project's issue [flights]: MAE per group (mean Euclidean norm of the error;
attitude as the quaternion geodesic angle) at h = 50 and, in ``sum``, summed over h = 1..50, on
the benchmark's own test trajectory type (not among the 17 flights in ../shared), on their
processed flights. Units: m, m/s, rad, rad/s.

NANODRONE_RERUN_RMSE_H50: RMSE per group at h = 50 on that same test type, as measured by the
issue's author (not by the paper): the published weights re-run on the stored test flights, and
a full-state ARX(1) fitted by least squares on the 17 flights. The benchmark's test type is not
available here, so these numbers are quoted, not reproduced.
"""
from __future__ import annotations

__all__ = ["NANODRONE_PUBLISHED", "NANODRONE_RERUN_RMSE_H50", "NANODRONE_SOURCE", "GROUPS"]

NANODRONE_SOURCE = ("Busetto et al., Nonlinear system identification for a nano-drone "
                    "benchmark, Control Eng. Practice 172 (2026) 106871, arXiv 2512.14450")
GROUPS = ("position", "velocity", "attitude", "rates")

# model -> group -> (MAE at h = 50, sum of MAE over h = 1..50)
NANODRONE_PUBLISHED = {
    "naive": {"position": (0.680, 17.79), "velocity": (1.475, 38.92),
              "attitude": (0.304, 8.21), "rates": (0.884, 29.09)},
    "physics": {"position": (0.127, 2.32), "velocity": (0.578, 10.62),
                "attitude": (0.254, 5.10), "rates": (0.884, 29.09)},
    "residual MLP": {"position": (0.171, 4.05), "velocity": (0.572, 12.58),
                     "attitude": (0.227, 6.06), "rates": (0.901, 35.57)},
    "Phys+Res": {"position": (0.112, 2.36), "velocity": (0.556, 10.40),
                 "attitude": (0.231, 6.15), "rates": (0.598, 28.99)},
    "LSTM": {"position": (0.257, 5.97), "velocity": (0.741, 16.72),
             "attitude": (0.233, 5.65), "rates": (1.241, 35.84)},
}

# group -> RMSE at h = 50; the attitude's best published value is quoted as a range
NANODRONE_RERUN_RMSE_H50 = {
    "best published": {"position": 0.087, "velocity": 0.410, "attitude": (0.136, 0.154),
                       "rates": 0.493},
    "ARX(1), 17 flights": {"position": 0.096, "velocity": 0.349, "attitude": 0.100,
                           "rates": 0.437},
}
