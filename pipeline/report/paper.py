"""The paper's published numbers, in one place, with where each comes from.

Source: the journal paper reproduced here (``shared/seeds/000_cd5ffea3b5428791.txt``,
UR5 under ROS: default effort PID vs computed-torque control, planned with
RRTConnect, simulated in Gazebo), section 4.3 "experimental results":

- Fig. 6 text: joint 1 maximum tracking error CTC e1 = 1.81E-3 rad,
  PID e2 = 3.348E-3 rad, "reduced by 45.9 %" = (PID - CTC) / PID.
- Table 3: joint error at the target position, x1e-5 rad, joints 1..6, and the
  printed reduction per joint, which is (PID - CTC) / CTC.
- Conclusion 2): peak joint velocities, CTC joint 4 -2.30 rad/s, joint 1
  -0.30 rad/s; PID joint 4 -0.83 rad/s, joint 1 -0.21 rad/s.
"""

from __future__ import annotations

PAPER_SOURCE = "seeds/000 (UR5, ROS PID vs CTC), section 4.3: Fig. 6 text, Table 3, conclusion 2)"

PAPER_BASELINE = "pid"
PAPER_CANDIDATE = "ctc"

# Fig. 6 text: joint 1 maximum tracking error [rad].
PAPER_JOINT1_MAX_ERROR_RAD = {"ctc": 1.81e-3, "pid": 3.348e-3}
# Printed "45.9 %": (PID - CTC) / PID x 100.
PAPER_JOINT1_MAX_ERROR_REDUCTION_PCT = 45.9

# Table 3: error at the target position [rad] (printed x1e-5), joints 1..6.
PAPER_FINAL_ERROR_RAD = {
    "ctc": (4.2397e-5, 2.3842e-5, 2.8337e-5, 5.0445e-5, 5.9948e-5, 0.0),
    "pid": (6.2498e-5, 4.6516e-5, 4.7873e-5, 6.2799e-5, 8.8528e-5, 0.0),
}
# Table 3's printed reduction [%]: (PID - CTC) / CTC x 100.
PAPER_FINAL_ERROR_REDUCTION_PCT = (47.4, 95.1, 68.9, 24.5, 47.6, 0.0)

# Conclusion 2): peak joint velocity [rad/s] by joint number (1-based).
PAPER_PEAK_VELOCITY_RAD_S = {
    "ctc": {1: -0.30, 4: -2.30},
    "pid": {1: -0.21, 4: -0.83},
}
