"""Names that must agree across modules: topics, message types, entity paths."""

from __future__ import annotations

TOPIC_JOINT_STATES = "/joint_states"
TOPIC_CONTROLLER_STATE = "/controller_state"
TOPIC_PLANNED_TRAJECTORY = "/planned_trajectory"
TOPIC_ROBOT_DESCRIPTION = "/robot_description"
TOPIC_TF = "/tf"
# The plant's true joint state (simulation only), beside the measured /joint_states.
TOPIC_GROUND_TRUTH = "/ground_truth/joint_states"

TYPE_JOINT_STATE = "sensor_msgs/msg/JointState"
TYPE_CONTROLLER_STATE = "control_msgs/msg/JointTrajectoryControllerState"
TYPE_JOINT_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"
TYPE_STRING = "std_msgs/msg/String"
TYPE_TF = "tf2_msgs/msg/TFMessage"

# MCAP metadata record holding the episode's full settings (JSON strings).
METADATA_EPISODE = "armlab.episode"

DEFAULT_PARAMS = "params.yaml"
DEFAULT_RECORDINGS_DIR = "recordings"
DEFAULT_REPORTS_DIR = "reports"

# "Error at the target": mean |error| over the last min(FINAL_WINDOW_S, hold / 2) seconds.
FINAL_WINDOW_S = 0.5
# A sample this close before the final window's start is inside it [s] (float noise).
FINAL_EDGE_S = 1e-9
# How an error is printed by every printer (the record and report consoles, report.md), so
# they agree to the printed digit: 4 significant digits.
ERROR_FORMAT = ".3e"

# Seeds: OMPL seeds are 32-bit and must be non-zero, and the planner passes seed + 1.
MAX_SEED = 2**32 - 2

# The plant every episode runs on (pipeline.model.mjcf builds it; every bag's plant
# settings record both). RK4 with the control period's zero-order hold: halving the step
# moves no metric of the default experiment by 5 % (benches/convergence.py).
PLANT_INTEGRATOR = "RK4"
# Joint friction sticks: MuJoCo's frictionloss constraint made stiff (tests/model/test_friction.py).
FRICTION_IMPEDANCE = 0.9999
PLANT_FRICTION = (
    "stick-slip Coulomb (frictionloss, solimpfriction "
    f"{FRICTION_IMPEDANCE:g}, solreffriction 2 physics steps) + viscous damping"
)
