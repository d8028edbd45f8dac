"""Training our walking policy (issue #14): the model-based teacher (`ZmpWalker`, a
gait plan with IMU balance feedback) distilled into an MLP by behaviour cloning and
DAgger, on this machine's CPU.

The recipe (`DistillConfig`; `legcal-bench train-policy` runs it):
- The student sees only what the robot measures and its own state, through the policy
  spec's terms (`student_terms`): gyro rate, gravity direction from the IMU filter,
  corrected encoder angles and velocities, its last action, a gait clock (sin, cos of
  the teacher's stride period) and a start-up clock (time since reset, clipped).
- Iteration 0 is behaviour cloning: the teacher walks `rollouts` episodes and every
  step is labelled with its joint targets. Each later iteration rolls out the mixture
  (the teacher's action with probability beta = `beta_decay`^i at each step, else the
  student's) and labels every visited state with the teacher's action (DAgger); the
  student is retrained on everything gathered so far.
- Every rollout is randomized: offsets uniform +-`offsets_deg` per joint (independent
  per leg), the realistic sensor noise (fresh seed), floor friction in `friction`, every
  body's mass scaled by 1 +- `mass_jitter`.
- Selection: after each iteration the pure student walks a fixed evaluation set (no
  offsets, `paper@<eval_deg>`, and `eval_rollouts` random patterns at +-`offsets_deg`);
  the checkpoint kept is the one upright in most of them (ties: upright in more of the
  two fixed patterns, then longest mean time upright, then lower validation loss),
  because DAgger is not monotone.

The seeds used here (training 60000+, evaluation 70000+) are disjoint from the
walking evaluation's (0..34 walks, 20000+ offset patterns).
"""

from __future__ import annotations

import time as _time
from dataclasses import asdict, dataclass, field

import numpy as np

from legcal_bench.evaluation.distill_config import DistillConfig
from legcal_bench.policies.observation import observation_size
from legcal_bench.policies.runner import PolicyRunner
from legcal_bench.policies.spec import ObsTerm, PolicySpec
from legcal_bench.policies.zmp_walker import TeacherRecipe, ZmpWalker

TRAIN_SEED_BASE = 60000
EVAL_SEED_BASE = 70000


def student_terms(recipe: TeacherRecipe) -> tuple[ObsTerm, ...]:
    stride = 2 * recipe.gait.step_period
    return (ObsTerm("ang_vel", (0.25,)), ObsTerm("gravity"), ObsTerm("joint_pos"), ObsTerm("joint_vel", (0.05,)),
            ObsTerm("last_action"), ObsTerm("phase", period=stride),
            ObsTerm("time", (1.0 / recipe.gait.start_s,), clip=2.0))


def student_spec(name: str, legmap, recipe: TeacherRecipe, teacher: ZmpWalker, cfg: DistillConfig, path, model_file,
                 model_format: str = "torchscript") -> PolicySpec:
    from legcal_bench.protocol.servos import servo_gains

    w = servo_gains(legmap)  # the gains `collect` uses
    return PolicySpec(name=name, path=path, model_file=model_file, model_format=model_format,
                      joints=tuple(legmap.joint_names), default_q=tuple(float(v) for v in teacher.default_q),
                      action_scale=cfg.action_scale, action_clip=None, kp=tuple(w.kp), kd=tuple(w.kd), torque_limit=None,
                      physics_hz=recipe.physics_hz, control_hz=recipe.control_hz, command=(0.0, 0.0, 0.0),
                      observation=student_terms(recipe))


class Student:
    """The MLP with its input normalization inside (so the exported file takes the
    spec's raw observation)."""

    def __init__(self, n_obs: int, n_act: int, hidden, mean: np.ndarray, std: np.ndarray, seed: int):
        import torch

        torch.manual_seed(seed)
        layers, k = [], n_obs
        for h in hidden:
            layers += [torch.nn.Linear(k, h), torch.nn.ELU()]
            k = h
        layers.append(torch.nn.Linear(k, n_act))

        class Net(torch.nn.Module):
            def __init__(self):
                super().__init__()
                self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
                self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
                self.mlp = torch.nn.Sequential(*layers)

            def forward(self, obs):
                return self.mlp((obs - self.mean) / self.std)

        self.net = Net()

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        import torch

        with torch.inference_mode():
            return self.net(torch.from_numpy(obs[None])).numpy()[0].astype(np.float64)


@dataclass
class Rollout:
    obs: np.ndarray
    labels: np.ndarray
    fallen_at: float | None
    seconds: float


def _randomize(env, rng: np.random.Generator, cfg: DistillConfig, nominal: dict) -> None:
    m = env.unwrapped.sim.model
    m.body_mass[:] = nominal["mass"] * (1 + rng.uniform(-1, 1, m.nbody) * cfg.mass_jitter)
    m.geom_friction[:, 0] = nominal["friction"] * rng.uniform(*cfg.friction)


def rollout(env, teacher: ZmpWalker, spec: PolicySpec, student: Student | None, beta: float, seed: int,
            offsets: np.ndarray, seconds: float, rng: np.random.Generator) -> Rollout:
    """One episode: the teacher's action with probability `beta` per step, else the
    student's; every step labelled with the teacher's (in the student's action units)."""
    u = env.unwrapped
    runner = PolicyRunner(spec, u.legmap, model=student if student is not None else lambda o: None)
    obs, info = env.reset(seed=seed, options={"offsets": offsets})
    teacher.reset()
    runner.reset()
    n = int(round(seconds / u.dt))
    O, L = np.empty((n, runner.n_obs), np.float32), np.empty((n, len(spec.joints)), np.float32)
    k = 0
    for k in range(n):
        t = u.sim.time
        o = runner.observation(obs, info, t)
        label = runner.action_of(teacher.act(obs, info, t))
        O[k], L[k] = o, label
        a = label if student is None or rng.random() < beta else student(o)
        obs, _, terminated, _, info = env.step(runner.targets(a))
        if terminated:
            break
    return Rollout(O[:k + 1], L[:k + 1], info["fallen_at"], float(u.sim.time))


@dataclass
class Evaluation:
    upright: int
    total: int
    mean_upright_s: float
    per_condition: list = field(default_factory=list)

    @property
    def fixed_upright(self) -> int:
        """Upright in the fixed-pattern conditions (none, paper@D): the ones every
        evaluation walks with many seeds."""
        return sum(r["upright"] for r in self.per_condition if not r["offsets"].startswith("random"))


def evaluate(env, spec: PolicySpec, student: Student, teacher: ZmpWalker, cfg: DistillConfig, legmap) -> Evaluation:
    """The pure student on the fixed selection set."""
    from legcal_bench.sim.offsets import resolve_offsets

    n = legmap.n_joints
    conds = [("none", np.zeros(n)), (f"paper@{cfg.eval_deg:g}", resolve_offsets(f"paper@{cfg.eval_deg:g}", legmap))]
    for i in range(cfg.eval_rollouts):
        r = np.random.default_rng(EVAL_SEED_BASE + 1000 + i)
        conds.append((f"random#{i}", r.uniform(-1, 1, n) * np.deg2rad(cfg.offsets_deg)))
    rows = []
    for i, (name, off) in enumerate(conds):
        r = rollout(env, teacher, spec, student, 0.0, EVAL_SEED_BASE + i, off, cfg.seconds, np.random.default_rng(0))
        rows.append({"offsets": name, "upright": r.fallen_at is None, "seconds": r.seconds})
    return Evaluation(sum(r["upright"] for r in rows), len(rows), float(np.mean([r["seconds"] for r in rows])), rows)


def train(legmap, recipe: TeacherRecipe, cfg: DistillConfig = DistillConfig(), name: str = "walker",
          log=lambda rec: None, progress: bool = True):
    """Run the recipe; returns (student, spec fields, history). `log(record)` gets one
    dict per iteration."""
    import torch
    from tqdm import tqdm

    from legcal_bench.envs.walking import WalkingEnv

    torch.set_num_threads(1)
    teacher = ZmpWalker(legmap, cfg.seconds, recipe.gait, recipe.feedback)
    spec = student_spec(name, legmap, recipe, teacher, cfg, None, None)
    env = WalkingEnv(robot=legmap, policy=spec, sensors="realistic")
    m = env.unwrapped.sim.model
    nominal = {"mass": m.body_mass.copy(), "friction": m.geom_friction[:, 0].copy()}
    rng = np.random.default_rng(cfg.seed)
    data_O, data_L = [], []
    student, best, history = None, None, []
    t_start = _time.perf_counter()
    bar = tqdm(total=cfg.iterations * (cfg.rollouts + cfg.eval_rollouts + 2), desc=f"train-policy {legmap.name}",
               unit="walk", disable=not progress)
    for it in range(cfg.iterations):
        beta = cfg.beta_decay ** it
        falls, t0 = 0, _time.perf_counter()
        for j in range(cfg.rollouts):
            seed = TRAIN_SEED_BASE + it * 1000 + j
            off = rng.uniform(-1, 1, legmap.n_joints) * np.deg2rad(cfg.offsets_deg)
            _randomize(env, rng, cfg, nominal)
            r = rollout(env, teacher, spec, None if it == 0 else student, beta, seed, off, cfg.seconds, rng)
            falls += r.fallen_at is not None
            data_O.append(r.obs)
            data_L.append(r.labels)
            bar.update(1)
        m.body_mass[:], m.geom_friction[:, 0] = nominal["mass"], nominal["friction"]
        O, L = np.concatenate(data_O), np.concatenate(data_L)
        if student is None:
            std = O.std(0)
            student = Student(O.shape[1], L.shape[1], cfg.hidden, O.mean(0), np.where(std > 1e-6, std, 1.0), cfg.seed)
        train_loss, val_loss = _fit(student, O, L, cfg, rng)
        ev = evaluate(env, spec, student, teacher, cfg, legmap)
        bar.update(cfg.eval_rollouts + 2)
        rec = {"iteration": it, "beta": beta, "samples": int(len(O)), "rollout_falls": falls,
               "train_loss": train_loss, "val_loss": val_loss, "eval_upright": ev.upright, "eval_total": ev.total,
               "eval_mean_upright_s": ev.mean_upright_s, "eval": ev.per_condition,
               "iteration_s": _time.perf_counter() - t0, "elapsed_s": _time.perf_counter() - t_start}
        key = (ev.upright, ev.fixed_upright, ev.mean_upright_s, -val_loss)
        if best is None or key > best[0]:
            best = (key, it, {k: v.detach().clone() for k, v in student.net.state_dict().items()})
        rec["selected_so_far"] = best[1]
        history.append(rec)
        log(rec)
        bar.set_postfix(upright=f"{ev.upright}/{ev.total}", best=best[1])
    bar.close()
    student.net.load_state_dict(best[2])
    return student, spec, {"iterations": history, "selected_iteration": best[1], "config": asdict(cfg),
                           "train_seconds": _time.perf_counter() - t_start}


def _fit(student: Student, O: np.ndarray, L: np.ndarray, cfg: DistillConfig, rng: np.random.Generator):
    """Adam on the mean squared action error; 5 % of the samples held out."""
    import torch

    n = len(O)
    perm = rng.permutation(n)
    n_val = max(1, n // 20)
    val, tr = perm[:n_val], perm[n_val:]
    Ot, Lt = torch.from_numpy(O), torch.from_numpy(L)
    opt = torch.optim.Adam(student.net.parameters(), lr=cfg.lr)
    net = student.net
    net.train()
    loss = torch.zeros(())
    for _ in range(cfg.train_steps):
        b = torch.from_numpy(tr[rng.integers(0, len(tr), cfg.batch)])
        loss = torch.nn.functional.mse_loss(net(Ot[b]), Lt[b])
        opt.zero_grad()
        loss.backward()
        opt.step()
    net.eval()
    with torch.no_grad():
        v = torch.nn.functional.mse_loss(net(Ot[torch.from_numpy(val)]), Lt[torch.from_numpy(val)]).item()
    return float(loss.item()), float(v)


def export(student: Student, spec: PolicySpec, out_dir, extra_notes: dict) -> dict:
    """TorchScript + ONNX files and one spec for each, written atomically."""
    import torch
    import yaml

    from legcal_bench.files.atomic import atomic_write, atomic_write_text

    n_obs = observation_size(spec)
    x = torch.zeros(1, n_obs)
    net = student.net.eval()
    atomic_write(out_dir / "policy.pt", lambda f: torch.jit.save(torch.jit.trace(net, x), f), mode="wb")

    def onnx(f):
        torch.onnx.export(net, (x,), f, dynamo=False, input_names=["obs"], output_names=["action"],
                          dynamic_axes={"obs": {0: "batch"}, "action": {0: "batch"}})

    atomic_write(out_dir / "policy.onnx", onnx, mode="wb")
    files = {}
    for fname, model, fmt in (("policy.yaml", "policy.pt", "torchscript"), ("policy.onnx.yaml", "policy.onnx", "onnx")):
        doc = spec_document(spec, model, fmt, extra_notes)
        atomic_write_text(out_dir / fname, "# Written by legcal-bench train-policy (legcal_bench/evaluation/distill.py)\n"
                          + yaml.safe_dump(doc, sort_keys=False, width=120, default_flow_style=None))
        files[fmt] = str(out_dir / fname)
    return files


def spec_document(spec: PolicySpec, model_file: str, fmt: str, notes: dict) -> dict:
    from legcal_bench.policies.spec import SPEC_FORMAT

    def term(t: ObsTerm) -> dict:
        d = {"term": t.term}
        if t.scale != (1.0,):
            d["scale"] = list(t.scale) if len(t.scale) > 1 else t.scale[0]
        if t.clip is not None:
            d["clip"] = t.clip
        if t.period is not None:
            d["period"] = t.period
        return d

    return {"format": SPEC_FORMAT, "name": spec.name, "model": {"file": model_file, "format": fmt},
            "joints": list(spec.joints), "default_q": [round(v, 6) for v in spec.default_q],
            "action": {"scale": spec.action_scale}, "pd": {"kp": list(spec.kp), "kd": list(spec.kd)},
            "rates": {"physics_hz": spec.physics_hz, "control_hz": spec.control_hz}, "command": list(spec.command),
            "observation": [term(t) for t in spec.observation], "notes": notes}
