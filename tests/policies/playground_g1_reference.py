"""Reference deployment of MuJoCo Playground's G1 joystick policy (29-DoF whole body),
transcribed with numpy, mujoco and onnxruntime only: the yardstick a policy spec for
this robot must reproduce (issue 40, item 4).

Material: ../shared/external/playground_g1/ (SOURCE.md: google-deepmind/mujoco_playground
at d5e6b47531328468da1eec33b8b304a00bb0873c). The reference Python there imports
Playground and JAX and cannot run here, so this module restates its formulas:

- `reference_observation`: `OnnxController.get_obs` in play_g1_joystick.py;
- `reference_phase_step`: the phase update at the end of `OnnxController.get_control`
  (the same formula as the end of `Joystick.step` in joystick.py);
- `reference_action_to_ctrl`: `data.ctrl[:] = ...` in `OnnxController.get_control`;
- `reset_reference` and the constants: `load_callback` in play_g1_joystick.py.

What this reproduces is the *play script's* deployment (no noise, fixed gait frequency,
the keyframe as the start, the MJCF's own position actuators). Where training
(joystick.py) differs, `TRAINING_NOTES` says how.

Layout of the 103-value observation (float32), in this order:

    [0:3]    local_linvel_pelvis  velocimeter at site imu_in_pelvis (site frame): privileged
    [3:6]    gyro_pelvis          gyro at site imu_in_pelvis (rad/s)
    [6:9]    gravity              site imu_in_pelvis's xmat^T @ [0, 0, -1] (true orientation)
    [9:12]   command              [vx m/s, vy m/s, yaw rate rad/s]
    [12:41]  qpos[7:] - default   29 joint angles (qpos order) minus keyframe knees_bent
    [41:70]  qvel[6:]             29 joint velocities
    [70:99]  last action          the network's previous raw output (zeros at reset)
    [99:103] cos(phase[0]), cos(phase[1]), sin(phase[0]), sin(phase[1])

The 29 joints of qpos[7:], the 29 actuators and the 29 network outputs are in the same
order (`JOINTS`): the scene XML lists its actuators in joint order, one per joint.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MATERIAL = Path(__file__).resolve().parents[3] / "shared" / "external" / "playground_g1"
SCENE_XML = MATERIAL / "scene_mjx_feetonly_flat_terrain.xml"
POLICY_ONNX = MATERIAL / "g1_policy.onnx"

# load_callback in play_g1_joystick.py.
CTRL_DT = 0.02  # s, one policy step (50 Hz)
SIM_DT = 0.002  # s, model.opt.timestep (500 Hz)
N_SUBSTEPS = 10  # round(CTRL_DT / SIM_DT)
KEYFRAME = 1  # "knees_bent": the reset state (mj_resetDataKeyframe) and the default angles
KEYFRAME_NAME = "knees_bent"
# OnnxController.__init__ in play_g1_joystick.py.
ACTION_SCALE = 0.5
GAIT_FREQ = 1.5  # Hz
INITIAL_PHASE = (0.0, np.pi)  # left, right: the feet half a cycle apart
OBS_SIZE = 103
N_ACTIONS = 29
INPUT_NAME, OUTPUT_NAME = "obs", "continuous_actions"  # the ONNX graph's (input [1, 103], output [1, 29])
# The play script's gamepad scales (the joystick's full deflection): beyond training's
# command ranges in vx and yaw rate (TRAINING_NOTES["command"]).
PLAY_COMMAND_SCALE = (1.5, 0.8, 2 * np.pi)

# The model's joint order: qpos[7:], qvel[6:], actuators, network outputs.
LEG_JOINTS = {
    side: tuple(f"{side}_{j}_joint" for j in ("hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch",
                                              "ankle_roll"))
    for side in ("left", "right")
}
WAIST_JOINTS = ("waist_yaw_joint", "waist_roll_joint", "waist_pitch_joint")
ARM_JOINTS = {
    side: tuple(f"{side}_{j}_joint" for j in ("shoulder_pitch", "shoulder_roll", "shoulder_yaw", "elbow",
                                              "wrist_roll", "wrist_pitch", "wrist_yaw"))
    for side in ("left", "right")
}
JOINTS = LEG_JOINTS["left"] + LEG_JOINTS["right"] + WAIST_JOINTS + ARM_JOINTS["left"] + ARM_JOINTS["right"]

# Sensors and sites get_obs reads (the scene's g1_mjx_feetonly.xml).
LINVEL_SENSOR = "local_linvel_pelvis"  # <velocimeter site="imu_in_pelvis">: the simulator's truth
GYRO_SENSOR = "gyro_pelvis"  # <gyro site="imu_in_pelvis">
IMU_SITE = "imu_in_pelvis"  # pelvis body, pos (0.04525, 0, -0.08339), no rotation

# What training (joystick.py default_config and Joystick, plus the domain randomization
# Playground's training applies) did that the play script does not. Not used by the
# reference functions; recorded for whoever writes the spec or compares results.
TRAINING_NOTES = {
    "source": "joystick.py (default_config, Joystick.reset/step/_get_obs/sample_command), base.py, randomize.py",
    "phase": ("never frozen: the freeze at |command| < 0.01 (phase held at pi) is commented out in Joystick.step, "
              "and the play script does not freeze it either, so at a zero command the policy keeps stepping in "
              "place; same fmod wrap in both"),
    "gait_freq_hz": ("per episode U(1.25, 1.5) in training (the comment says U(1.0, 1.5), the code draws "
                     "minval=1.25), fixed 1.5 in the play script"),
    "initial_phase": "[0, pi] in both",
    "command": ("training: vx U(-1, 1) m/s, vy U(-0.5, 0.5) m/s, yaw rate U(-1, 1) rad/s, all three zeroed with "
                "probability 0.1, resampled every 500 control steps (10 s); command_config a/b are defined but "
                "unused by sample_command. Play: gamepad deflection x (1.5, 0.8, 2 pi), i.e. up to 1.5 m/s and "
                "6.3 rad/s, outside the trained range"),
    "observation_noise": ("training: uniform +-(level 1.0 x scale) added to linvel 0.1 m/s, gyro 0.2 rad/s, "
                          "gravity 0.05, joint_pos 0.03 rad, joint_vel 1.5 rad/s (not to command, last action, "
                          "phase); play: none"),
    "observation_scales": "none in either: every term enters raw (no per-term scaling or clipping)",
    "history_len": "1 (no observation stacking); the critic's privileged_state is not the policy's input",
    "action": ("motor_targets = default_pose + 0.5 * action in both, no clipping of the action; the position "
               "actuators' ctrlrange (= joint range, inheritrange=1) clamps the target in MuJoCo; last_act is the "
               "unclipped network output in both"),
    "actuators": ("the MJCF's own <position> actuators in both (no PD of Playground's): kp 75 (hips, knees, "
                  "waist, shoulders, elbows), 20 (ankle pitch), 2 (ankle roll, wrists); no kv: the damping is "
                  "the joints' (2, ankle pitch 1, ankle roll and wrists 0.2), frictionloss 0.1; torque limited "
                  "per joint by actuatorfrcrange (hip pitch/yaw 88, hip roll/knee 139, ankles 50, waist yaw 88, "
                  "waist roll/pitch 50, arms 25, wrist pitch/yaw 5 N m)"),
    "domain_randomization": ("randomize.py (Playground's G1 domain_randomize, applied by its training script; "
                             "not in the shipped material, read from a public fork's copy, yursds/mujoco_playground "
                             "mujoco_playground/_src/locomotion/g1/randomize.py; unverified against d5e6b47): "
                             "foot-floor pair friction U(0.4, 1.0) (as written it overwrites pair 0's draw, so "
                             "only the right foot's pair is randomized), dof frictionloss x U(0.5, 2.0), "
                             "armature x U(1.0, 1.05), every body mass x U(0.9, 1.1), torso mass + U(-1, 1) kg, "
                             "qpos0 + U(-0.05, 0.05)"),
    "floor_friction": ("scene: the feet touch the floor only through <pair> contacts (all geoms have contype = "
                       "conaffinity = 0) with friction 0.6 (sliding 0.6, 0.6; torsional 0.005; rolling 1e-4), "
                       "condim 3; the floor geom's own friction 1.0 is unused. Training: the same 0.6, "
                       "randomized as above; play: 0.6"),
    "reset": ("training: keyframe knees_bent with x, y + U(-0.5, 0.5) m, yaw U(-3.14, 3.14), joint angles x "
              "U(0.5, 1.5), base velocity U(-0.5, 0.5) per axis, ctrl = those angles; play: the keyframe exactly "
              "(mj_resetDataKeyframe, ctrl from the keyframe)"),
    "pushes": "training: every U(5, 10) s a base velocity kick of U(0.1, 2.0) m/s in a random direction; play: none",
    "episode": "1000 control steps (20 s); termination when the torso's up vector points down or the feet touch",
    "simulator": ("training: MJX (impl 'warp'), ctrl_dt 0.02, sim_dt 0.002, the XML's solver options (Euler, "
                  "eulerdamp disabled, iterations 3, ls_iterations 5); play: C MuJoCo with the same model"),
    "restricted_joint_range": "False (the XML's joint ranges and ctrlranges are used) in training",
}


def joint_order_check(model) -> None:
    """Assert the order this module assumes: qpos[7:] joints = actuators = `JOINTS`."""
    import mujoco

    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(1, model.njnt)]
    assert tuple(names) == JOINTS, names
    assert [int(model.jnt_qposadr[j]) for j in range(1, model.njnt)] == list(range(7, 7 + N_ACTIONS))
    acts = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, int(model.actuator_trnid[a, 0]))
            for a in range(model.nu)]
    assert tuple(acts) == JOINTS, acts


def default_angles(model) -> np.ndarray:
    """The policy's default pose: keyframe knees_bent's qpos[7:] (29)."""
    return np.array(model.key_qpos[KEYFRAME][7:], dtype=float)


def load_reference_model(path: Path | str = SCENE_XML):
    """The scene as `load_callback` prepares it: the flat-terrain scene with timestep SIM_DT."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    model.opt.timestep = SIM_DT
    return model


def reset_reference(model, data) -> None:
    """`mj_resetDataKeyframe(model, data, 1)` then forward (sensors valid for the first observation)."""
    import mujoco

    mujoco.mj_resetDataKeyframe(model, data, KEYFRAME)
    mujoco.mj_forward(model, data)


def initial_phase() -> np.ndarray:
    return np.array(INITIAL_PHASE, dtype=float)


def reference_observation(model, data, default_angles, phase, command, last_action) -> np.ndarray:
    """The 103-value observation of `OnnxController.get_obs` (play_g1_joystick.py), float32."""
    linvel = data.sensor(LINVEL_SENSOR).data
    gyro = data.sensor(GYRO_SENSOR).data
    R = data.site_xmat[model.site(IMU_SITE).id].reshape(3, 3)
    gravity = R.T @ np.array([0.0, 0.0, -1.0])  # world down in the IMU site's frame
    phase = np.asarray(phase, dtype=float)
    obs = np.concatenate([
        linvel,
        gyro,
        gravity,
        np.asarray(command, dtype=float),
        data.qpos[7:] - np.asarray(default_angles, dtype=float),
        data.qvel[6:],
        np.asarray(last_action, dtype=float),
        np.cos(phase),  # cos of both feet first, then sin: [cos l, cos r, sin l, sin r]
        np.sin(phase),
    ])
    assert obs.shape == (OBS_SIZE,), obs.shape
    return obs.astype(np.float32)


def reference_phase_step(phase, ctrl_dt: float = CTRL_DT, gait_freq: float = GAIT_FREQ) -> np.ndarray:
    """One control step of the gait clock, wrapped to [-pi, pi) as the script does:
    fmod(phase + 2 pi f dt + pi, 2 pi) - pi (np.fmod: the sign follows the dividend)."""
    phase_dt = 2 * np.pi * gait_freq * ctrl_dt
    return np.fmod(np.asarray(phase, dtype=float) + phase_dt + np.pi, 2 * np.pi) - np.pi


def reference_action_to_ctrl(action, default_angles, action_scale: float = ACTION_SCALE) -> np.ndarray:
    """Position-actuator targets: action * scale + default angles (no clipping here;
    MuJoCo clamps ctrl to the actuators' ctrlrange)."""
    return np.asarray(action, dtype=float) * action_scale + np.asarray(default_angles, dtype=float)


class ReferenceController:
    """The play script's `OnnxController` with a constant command instead of a gamepad.

    `step(model, data)`: one control step (observe, act, N_SUBSTEPS physics steps).
    `control(model, data)` alone needs the kinematics and sensors of the current state
    (after `mj_forward`; right after `mj_step` they are one physics step old). The
    script runs get_control as mjcb_control inside every mj_step (after the position
    and velocity stages, so its sensors are current) and acts on every N_SUBSTEPS-th
    call, the first at the 10th (t = 0.018 s, the keyframe's ctrl held until then);
    `step` acts at t = 0 and every CTRL_DT after: the same schedule, shifted by 9
    physics steps."""

    def __init__(self, model, command=(0.5, 0.0, 0.0), policy_path: Path | str = POLICY_ONNX,
                 gait_freq: float = GAIT_FREQ):
        import onnxruntime as rt

        opts = rt.SessionOptions()
        opts.intra_op_num_threads = opts.inter_op_num_threads = 1
        self.session = rt.InferenceSession(str(policy_path), opts, providers=["CPUExecutionProvider"])
        self.default = default_angles(model)
        self.command = np.asarray(command, dtype=float)
        self.gait_freq = gait_freq
        self.reset()

    def reset(self) -> None:
        self.phase = initial_phase()
        self.last_action = np.zeros(N_ACTIONS, dtype=np.float32)

    def control(self, model, data) -> np.ndarray:
        obs = reference_observation(model, data, self.default, self.phase, self.command, self.last_action)
        action = self.session.run([OUTPUT_NAME], {INPUT_NAME: obs.reshape(1, -1)})[0][0]
        self.last_action = action.copy()
        data.ctrl[:] = reference_action_to_ctrl(action, self.default)
        self.phase = reference_phase_step(self.phase, CTRL_DT, self.gait_freq)
        return obs

    def step(self, model, data) -> np.ndarray:
        """One control step: forward (current sensors), act, N_SUBSTEPS physics steps;
        the observation the network saw."""
        import mujoco

        mujoco.mj_forward(model, data)
        obs = self.control(model, data)
        mujoco.mj_step(model, data, nstep=N_SUBSTEPS)
        return obs
