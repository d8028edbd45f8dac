"""Every number taken from the paper, in one place, with the section it comes from.

Lu et al., "Contact-Constrained Lower-Limb Joint-Offset Calibration for Humanoid
Robots" (RA-L), `../shared/paper/contact-constrained-calibration.tex`. Angles as the
paper gives them (degrees where it prints degrees); the injection and the solver
bound in radians, as the method uses them. Nothing else in legcal-bench writes
these values again: it imports them from here.
"""

from __future__ import annotations

# --- §V-A Setup and Table II ("Injected" column): the injection, per leg, by role (rad).
INJECTION_RAD = {
    "hip_pitch": 0.03, "hip_roll": 0.04, "hip_yaw": -0.02,
    "knee": -0.04, "ankle_pitch": 0.02, "ankle_roll": -0.03,
}

# --- §III-D Optimization Objective: the platform-specific operating settings.
# (lambda_f, lambda_g, lambda_q, lambda_knee) and W_q per leg in the platform's joint order.
A3_OPERATING = dict(lambda_f=2.0, lambda_g=10.0, lambda_q=0.01, lambda_knee=100.0, w_q=(1, 1, 1, 1.5, 1.5, 1.5))
A2_OPERATING = dict(lambda_f=1.0, lambda_g=100.0, lambda_q=1.0, lambda_knee=0.0, w_q=(0.5, 0.5, 0.5, 1, 1.5, 1.5))
# §V-A Controlled MuJoCo comparison: translation scaled by 1 mm, rotation/normal by 1 mrad.
MATCHED_UNIT_SCALE = 1000.0

# --- §III-E Alternating Optimization.
OFFSET_BOUND_RAD = 0.08
INNER_MAX_ITERATIONS = 200
INNER_FTOL = 1e-8
OUTER_MAX_ITERATIONS = 15

# --- §III-F Data Preprocessing.
GYRO_GUARD_RAD_S = 0.5
LOCAL_MEAN_WINDOW_S = 2.5
ROTATION_RESIDUAL_MAX_DEG = 5.0
N_MAX_PER_STANCE = 500
TRIM_FRACTION = 0.1

# --- §IV-D Algebraic resolution: the straight-leg standing phase lasts roughly 5 s.
STANDING_S = 5.0

# --- §V-B A3 Simulation Results.
ZERO_NOISE_RECOVERY_DEG = 1.2e-13  # "below"
WELD_FLOOR_RMS_DEG = 0.092
CONTACT_FLOOR_RMS_DEG = 0.121
A3_SIM_TABLE = dict(rms_deg=0.120, max_deg=0.274, kappa_H_reg=1.11e4)  # Table I, one squat stance, 450 frames

# --- §V-C Real-machine results (Table II): base offsets (deg), left leg then right, platform order.
A2_PLATFORM_ORDER = ("hip_roll", "hip_yaw", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")
A3_PLATFORM_ORDER = ("hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch", "ankle_roll")
A2_BASE_DEG = (0.430, -1.127, 0.244, 1.154, -0.450, 0.020, 0.521, 1.115, 0.735, 0.380, -0.858, -1.386)
A3_BASE_DEG = (1.035, 0.495, 0.273, -0.208, -0.850, 0.340, 1.001, -0.588, -0.194, -0.090, 0.024, 0.427)
REAL_PAIRED_DELTA_RMS_DEG = {"a2": 0.012, "a3": 0.061}
REAL_KAPPA_H_REG = {"a2": 5.03e3, "a3": 72.27}
# Common weights, no prior: kappa(H_data), and with the mean recomputed during differentiation.
REAL_MATCHED_KAPPA_H_DATA = {"a2": 4340.79, "a3": 333.23}
REAL_MATCHED_KAPPA_H_DATA_MEAN_RECOMPUTED = {"a2": 6254.53, "a3": 771.61}
# The controlled MuJoCo pair: (kappa(J_data), kappa(H_data)).
ORDERING_PAIR_KAPPA = {"roll->yaw->pitch": (348.90, 121728.69), "pitch->roll->yaw": (90.69, 8224.49)}
# Matched data-only A2: knee-prior centre moved from -1 to +1 deg.
KNEE_SENSITIVITY_INDIVIDUAL_DEG = (0.59, 1.90)
KNEE_SENSITIVITY_PITCH_SUMS_MAX_DEG = 0.0071

# --- §V-E Non-injection held-out validation: foot-height RMS (mm), before -> after.
HELDOUT_FOOT_HEIGHT_MM = {"a3": (4.26, 2.20), "a2": (8.03, 1.43)}
HELDOUT_SESSIONS = 3
HELDOUT_FRAMES_PER_SESSION = 500

# --- §V-F External validation (leg odometry vs LiDAR, Table III).
LIDAR_VERTICAL_DRIFT_M_PER_DEG = 1.04
LIDAR_RMS_MM = {"vertical": (319, 238), "forward": (287, 285), "lateral": (287, 288), "total_3d": (576, 494)}
LIDAR_VERTICAL_REDUCTION = 0.255

# --- §V-G Closed-loop simulation: 35 trials at 3 deg, RMS deviations (mm), before -> after.
CLOSED_LOOP_TRIALS = 35
CLOSED_LOOP_OFFSET_DEG = 3.0
CLOSED_LOOP_FOOT_STRIKE_MM = (1190.61, 26.57)
CLOSED_LOOP_PELVIS_MM = (1224.10, 27.16)

# --- §V-H Stance diversity (Table IV, real A2, H_reg): stances -> (eig0, eig1, eig2, kappa).
STANCE_DIVERSITY = {1: (1.1, 2.4, 16.3, 1.27e5), 2: (44.4, 76.8, 387.8, 6.19e3),
                    3: (91.4, 177.5, 753.4, 4.52e3), 4: (109.8, 558.9, 1050.6, 5.03e3)}

# --- §V-I Ablation: removing the flat-ground term shifts hip roll/yaw by 2-5 deg;
# the A3 knee prior takes kappa(H_reg) from about 333 to 72.27.
NO_FLAT_HIP_SHIFT_DEG = (2.0, 5.0)
KNEE_ABLATION_KAPPA_H_REG = {"without": 333.0, "with": 72.27}
