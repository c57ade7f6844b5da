"""Pitch/roll estimation from a simulated IMU on real car motion (KITTI ground truth).

IMU at 100 Hz from the KITTI odometry ground-truth poses of sequences 00-10 (10 Hz taken as
exactly 0.1 s; positions and Euler angles fitted with smoothing splines, see
``jbevo.data.synthetic.imu``), EuRoC ADIS16448 noise plus a turn-on gyro bias, one seed per sequence.
Frames are scored against the smoothed motion's pitch and roll; every method starts from the true
attitude at frame 0.

* accel only: the tilt of each frame's mean specific force;
* gyro only: exact Euler-rate integration of the gyro;
* DUKF hand-set: the pitch/roll UKF with hand-set Q, R;
* DUKF learned: Q, R learned with optax (Adam) through the filter on 00-08 (windows of
  ``--window`` frames, vmapped), tested on 09 and 10;
* DUKF + gyro bias: the same with a gyro-bias state (still IMU only), hand-set and learned;
* motion-compensated: the measurement minus the predicted body acceleration ``dv/dt + w x v``,
  with a gyro-bias state whose share of ``w x v`` the measurement model predicts; Q and R learned
  the same way. The planar body-frame velocity v stands in
  for the odometry's: the true one (world velocity turned by the yaw) plus N(0, ``--speed-noise``)
  per axis and frame; w is the frame's mean gyro.
* speed-aided (BEVO's filter, :class:`jbevo.inertial.speed_aided.SpeedAidedAttitude`): the forward
  accelerometer integrated into a speed state that the stand-in's forward speed measures, roll
  from the lateral tilt; hand-set and learned the same way.

``diagnostic_rmse_deg_fitted_on_test`` holds, for the DUKF, the DUKF + gyro bias and the
motion-compensated filter, the RMSE on 09 and 10 after fitting Q and R (Adam, same steps) on
the whole of 09 and 10 themselves: not a result, but about the best the filter's structure reaches
on those drives, to tell an accuracy the structure cannot reach from one that training misses.

``rmse_deg_accel_bias_tilt`` is the RMS of the tilt that the simulated accelerometer's bias
(random walk from zero, EuRoC's 3.0e-3 m/s^3/sqrt(Hz)) fakes on 09 and 10: an error that is
body-fixed like gravity's tilt and that no filter here can observe.

Writes ``benchmarks/results/attitude.json`` (RMSE in degrees over all frames of 09 and 10, pitch
and roll pooled) and takes ``bev_per_s`` from ``benchmarks/results/bev.json`` if present.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/attitude.py [--steps 300]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optax  # noqa: E402

from jbevo.data import pose_files  # noqa: E402
from jbevo.data.kitti_frames import body_poses_from_kitti  # noqa: E402
from jbevo.data.synthetic.imu import ADIS16448, planar_body_velocity, simulate_imu  # noqa: E402
from jbevo.files import write_json_atomic  # noqa: E402
from jbevo.inertial.attitude_filter import AttitudeFilter, integrate_gyro  # noqa: E402
from jbevo.inertial.kinematics import GRAVITY, tilt_measurements  # noqa: E402
from jbevo.inertial.speed_aided import AttitudeState, SpeedAidedAttitude  # noqa: E402

TRAIN = [f"{i:02d}" for i in range(9)]
TEST = ["09", "10"]
SAMPLES = 10  # IMU samples per frame
DT = 0.01


def load_sequence(root: Path, name: str, speed_noise: float) -> dict:
    gt = pose_files.read_kitti(root / "kitti_odom" / "gt_poses" / f"{name}.txt").poses
    body = body_poses_from_kitti(gt)
    t = 0.1 * np.arange(len(gt))
    d = simulate_imu(t, body, rate_hz=1 / DT, noise=ADIS16448, seed=int(name))
    n = len(gt) - 1
    gyro = d.gyro[: n * SAMPLES].reshape(n, SAMPLES, 3)
    accel = d.accel[: n * SAMPLES].reshape(n, SAMPLES, 3)
    rng = np.random.default_rng(100 + int(name))
    # The odometry's planar body-frame velocity (a stand-in until BEVO's own is available): the
    # true world velocity turned into the body's heading, plus noise.
    vb = planar_body_velocity(d)[: n * SAMPLES].reshape(n, SAMPLES, 2).mean(1)
    vb = vb + rng.normal(0, speed_noise, (n, 2))
    # The tilt the accelerometer's own bias fakes (small angles: pitch -b_x / g, roll b_y / g) at
    # the end of each frame: body-fixed like gravity's tilt, so no filter here can tell them apart.
    ab = d.accel_bias[SAMPLES - 1 : n * SAMPLES : SAMPLES]
    return {
        "accel_bias_tilt": np.stack([-ab[:, 0], ab[:, 1]], -1) / GRAVITY,
        "gyro": gyro,
        "accel": accel,
        "velocity": vb,
        "truth": d.frame_euler[1:, 1:3],
        "initial": d.frame_euler[0, 1:3],
        "truth_all": d.frame_euler[:, 1:3],
    }


def windows(seqs: list[dict], length: int) -> dict:
    """Non-overlapping windows of ``length`` frames, each starting from its true attitude."""
    out = {k: [] for k in ("gyro", "accel", "velocity", "truth", "initial")}
    for s in seqs:
        for start in range(0, len(s["truth"]) - length + 1, length):
            sl = slice(start, start + length)
            out["gyro"].append(s["gyro"][sl])
            out["accel"].append(s["accel"][sl])
            out["velocity"].append(s["velocity"][sl])
            out["truth"].append(s["truth"][sl])
            out["initial"].append(s["truth_all"][start])
    return {k: jnp.asarray(np.stack(v)) for k, v in out.items()}


def run(f: AttitudeFilter, s: dict, compensated: bool):
    return f(s["gyro"], s["accel"], s["initial"], s["velocity"] if compensated else None)


def adam_step(loss, lr: float, f):
    """``(step, state)``: a compiled Adam step ``step(f, state, data) -> (f, state, loss)`` on
    ``loss(f, data)`` over the array leaves of ``f``, and its initial state. ``data`` is an
    argument of the compiled step, not a constant baked into it."""
    opt = optax.adam(lr)

    @eqx.filter_jit
    def step(f, state, data):
        value, grads = eqx.filter_value_and_grad(loss)(f, data)
        updates, state = opt.update(grads, state)
        return eqx.apply_updates(f, updates), state, value

    return step, opt.init(eqx.filter(f, eqx.is_array))


def fit(f, loss, data, steps: int, lr: float):
    """Adam on ``loss(f, data)`` (:func:`adam_step`); the training RMSE every 25 steps."""
    step, state = adam_step(loss, lr, f)
    history = []
    for i in range(steps):
        f, state, value = step(f, state, data)
        if i % 25 == 0 or i == steps - 1:
            history.append((i, float(np.degrees(np.sqrt(value)))))
            print(f"  step {i:4d}  train RMSE {history[-1][1]:.4f} deg", flush=True)
    return f, history


def train(f: AttitudeFilter, data: dict, compensated: bool, steps: int, lr: float) -> tuple[AttitudeFilter, list]:
    def loss(f, data):
        est = jax.vmap(lambda g, a, i, c: f(g, a, i, c if compensated else None))(
            data["gyro"], data["accel"], data["initial"], data["velocity"]
        )
        return jnp.mean((est - data["truth"]) ** 2)

    return fit(f, loss, data, steps, lr)


def speed_aided_beliefs(f: SpeedAidedAttitude, gyro, accel, initial, velocity) -> AttitudeState:
    """The speed-aided filter (BEVO's) over one window, measuring the odometry stand-in's forward
    speed, from the true initial attitude and speed: its belief after every frame."""
    start = AttitudeState.initial(initial, velocity[0, 0], 0.03, 0.005, 0.1)

    def step(state, x):
        g, a, v = x
        state = f.update_lateral_tilt(f.update_speed(f.predict(state, g, a), v), g, a).astype(initial.dtype)
        return state, state

    return jax.lax.scan(step, start, (gyro, accel, velocity[:, 0]))[1]


def run_speed_aided(f: SpeedAidedAttitude, gyro, accel, initial, velocity):
    """:func:`speed_aided_beliefs`' pitch and roll per frame."""
    return speed_aided_beliefs(f, gyro, accel, initial, velocity).pitch_roll


def run_speed_aided_smoothed(f: SpeedAidedAttitude, gyro, accel, initial, velocity):
    """Offline: the unscented RTS smoother over :func:`speed_aided_beliefs` (pitch and roll)."""
    return f.smooth(speed_aided_beliefs(f, gyro, accel, initial, velocity), gyro, accel).pitch_roll


def train_speed_aided(f: SpeedAidedAttitude, data: dict, steps: int, lr: float) -> tuple[SpeedAidedAttitude, list]:
    def loss(f, data):
        est = jax.vmap(lambda g, a, i, v: run_speed_aided(f, g, a, i, v))(
            data["gyro"], data["accel"], data["initial"], data["velocity"]
        )
        return jnp.mean((est - data["truth"]) ** 2)

    return fit(f, loss, data, steps, lr)


def rmse_deg(estimates: list[np.ndarray], truths: list[np.ndarray]) -> float:
    err = np.concatenate([np.asarray(e) - t for e, t in zip(estimates, truths)])
    return float(np.degrees(np.sqrt(np.mean(err**2))))


def options(doc: str, steps: int, record: str) -> argparse.ArgumentParser:
    """The options the attitude benchmarks share (reference data, training, the stand-in's noise,
    the record written)."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=os.environ.get("JBEVO_REFERENCE_DATA"))
    parser.add_argument("--steps", type=int, default=steps)
    parser.add_argument("--lr", type=float, default=0.05)
    parser.add_argument("--window", type=int, default=1000)
    parser.add_argument("--speed-noise", type=float, default=0.05)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / record)
    return parser


def reference_data(args: argparse.Namespace) -> Path:
    if args.data is None:
        raise SystemExit("set JBEVO_REFERENCE_DATA or pass --data (the reference-data folder)")
    return args.data


def main() -> None:
    args = options(__doc__ or "", 300, "attitude.json").parse_args()
    reference_data(args)

    t0 = time.time()
    train_seqs = [load_sequence(args.data, n, args.speed_noise) for n in TRAIN]
    test_seqs = [load_sequence(args.data, n, args.speed_noise) for n in TEST]
    data = windows(train_seqs, args.window)
    truths = [s["truth"] for s in test_seqs]
    test_jnp = [{k: jnp.asarray(v) for k, v in s.items()} for s in test_seqs]
    print(
        f"simulated IMU for {len(TRAIN) + len(TEST)} sequences in {time.time() - t0:.1f} s; "
        f"{data['gyro'].shape[0]} training windows of {args.window} frames"
    )

    results = {}
    results["rmse_deg_accel_bias_tilt"] = rmse_deg([s["accel_bias_tilt"] for s in test_seqs], [0.0, 0.0])
    results["rmse_deg_accel_only"] = rmse_deg([tilt_measurements(jnp.asarray(s["accel"])) for s in test_seqs], truths)

    def gyro_only(s):
        def step(x, g):
            x = integrate_gyro(x, g, DT)
            return x, x

        return jax.lax.scan(step, jnp.asarray(s["initial"]), jnp.asarray(s["gyro"]))[1]

    results["rmse_deg_gyro_only"] = rmse_deg([jax.jit(gyro_only)(s) for s in test_seqs], truths)

    handset = AttitudeFilter.create(dt=DT)
    run_jit = eqx.filter_jit(run)
    results["rmse_deg_dukf_handset"] = rmse_deg([run_jit(handset, s, False) for s in test_seqs], truths)

    print("training the DUKF (Q, R) on 00-08")
    learned, hist = train(handset, data, False, args.steps, args.lr)
    results["rmse_deg_dukf_learned"] = rmse_deg([run_jit(learned, s, False) for s in test_seqs], truths)

    print("training the DUKF with a gyro-bias state (IMU only, uncompensated) on 00-08")
    db0 = AttitudeFilter.create(dt=DT, gyro_bias=True)
    results["rmse_deg_dukf_gyro_bias_handset"] = rmse_deg([run_jit(db0, s, False) for s in test_seqs], truths)
    db, hist_db = train(db0, data, False, args.steps, args.lr)
    results["rmse_deg_dukf_gyro_bias_learned"] = rmse_deg([run_jit(db, s, False) for s in test_seqs], truths)

    print("training the motion-compensated DUKF with gyro bias on 00-08")
    mc0 = db0  # the same hand-set filter, its measurement compensated
    results["rmse_deg_motion_compensated_handset"] = rmse_deg([run_jit(mc0, s, True) for s in test_seqs], truths)
    mc, hist_mc = train(mc0, data, True, args.steps, args.lr)
    results["rmse_deg_motion_compensated"] = rmse_deg([run_jit(mc, s, True) for s in test_seqs], truths)

    print("the speed-aided filter (BEVO's attitude), measuring the stand-in's forward speed")
    sa0 = SpeedAidedAttitude.create(dt=DT)
    run_sa = eqx.filter_jit(
        lambda f, s: run_speed_aided(f, *(jnp.asarray(s[k], jnp.float32) for k in ("gyro", "accel", "initial", "velocity")))
    )
    results["rmse_deg_speed_aided_handset"] = rmse_deg([run_sa(sa0, s) for s in test_seqs], truths)
    sa, hist_sa = train_speed_aided(sa0, data, args.steps, args.lr)
    results["rmse_deg_speed_aided"] = rmse_deg([run_sa(sa, s) for s in test_seqs], truths)
    # Offline: the unscented RTS smoother over the same filter's beliefs (hand-set and learned).
    run_sas = eqx.filter_jit(
        lambda f, s: run_speed_aided_smoothed(
            f, *(jnp.asarray(s[k], jnp.float32) for k in ("gyro", "accel", "initial", "velocity"))
        )
    )
    results["rmse_deg_speed_aided_smoothed_handset"] = rmse_deg([run_sas(sa0, s) for s in test_seqs], truths)
    results["rmse_deg_speed_aided_smoothed"] = rmse_deg([run_sas(sa, s) for s in test_seqs], truths)

    # Diagnostic, not a result: Q and R fitted on the whole test drives and scored on them: about
    # the best each filter's structure reaches there.
    print("diagnostic: Q, R fitted on the test drives themselves")
    fitted = {}
    for name, f0, compensated in (("dukf", handset, False), ("dukf_gyro_bias", db0, False), ("motion_compensated", mc0, True)):
        f, _ = fit(
            f0,
            lambda f, seqs, c=compensated: (
                sum(jnp.sum((run(f, s, c) - s["truth"]) ** 2) for s in seqs) / sum(len(s["truth"]) for s in seqs)
            ),
            test_jnp,
            args.steps,
            args.lr,
        )
        fitted[name] = rmse_deg([run_jit(f, s, compensated) for s in test_seqs], truths)
    results["diagnostic_rmse_deg_fitted_on_test"] = fitted

    results["learned_std_deg"] = {
        "dukf_motion_per_frame": np.degrees(np.exp(np.asarray(learned.motion_noise.log_std))).tolist(),
        "dukf_measurement": np.degrees(np.exp(np.asarray(learned.measurement_noise.log_std))).tolist(),
        "mc_motion_per_frame": np.degrees(np.exp(np.asarray(mc.motion_noise.log_std))).tolist(),
        "mc_measurement": np.degrees(np.exp(np.asarray(mc.measurement_noise.log_std))).tolist(),
    }
    results["training_history_deg"] = {
        "dukf": hist,
        "dukf_gyro_bias": hist_db,
        "motion_compensated": hist_mc,
        "speed_aided": hist_sa,
    }
    results["improvement_vs_accel_only"] = {
        "dukf_learned": results["rmse_deg_accel_only"] / results["rmse_deg_dukf_learned"],
        "motion_compensated": results["rmse_deg_accel_only"] / results["rmse_deg_motion_compensated"],
    }
    bev = Path(__file__).parent / "results" / "bev.json"
    if bev.exists():
        results["bev_per_s"] = json.loads(bev.read_text())["bev_per_s"]
    results["config"] = {
        "train": TRAIN,
        "test": TEST,
        "window": args.window,
        "steps": args.steps,
        "lr": args.lr,
        "speed_noise_m_s": args.speed_noise,
        "imu": "ADIS16448 + 0.2 deg/s turn-on gyro bias, 100 Hz",
        "frame_dt_s": 0.1,
        "smoothing": 0.01,
        "seconds": time.time() - t0,
    }
    write_json_atomic(args.out, results)
    for k, v in results.items():
        if k.startswith("rmse") or k == "bev_per_s":
            print(f"{k:40s} {v:10.4f}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
