"""Pitch and roll on real IMUs: the KITTI odometry IMU (the car's OXTS RT3003, 10 rows per frame)
against the ground truth of 00-10, and the EuRoC drone IMU (ADIS16448, 200 Hz) against motion
capture; jbevo's filters and the ``ahrs`` package's in the same run.

KITTI. Frames at a nominal 0.10365 s (the mean step of 00's ``times.txt``; the other sequences'
times are not in the reference data). The IMU is calibrated per recording day, as KITTI
calibrates its rig (2011_10_03: 00-02; 2011_09_30: 04-08, applied to 09 and 10 too), on the
training and validation drives only (:func:`jbevo.inertial.calibration.calibrate`: mounting,
time offset, gyro scale and biases, with jackknife uncertainties), applied to every drive of the
day and resampled at 10 instants per frame; each
drive's ground truth is levelled by the gravity its own accelerometer finds
(:func:`~jbevo.inertial.calibration.gravity_up`), the truth every score is taken against
(pitch and roll pooled, all frames of 09 and 10, every method starting from the true attitude at
frame 0). Rows: tilt only, gyro only, the DUKF (hand-set; Q and R learned), with a gyro-bias
state, motion-compensated (true planar body velocity + N(0, 5 cm/s) standing in for the
odometry's, as in ``attitude.py``), the speed-aided filter (BEVO's; the same stand-in's forward
speed) and, offline, its beliefs through the unscented RTS smoother
(``SpeedAidedAttitude.smooth``, the filter's own noise). Learned filters: Adam through the filter on 00-07 (windows of ``--window`` frames from
the true attitude), the step chosen on 08 (whole drive), tested on 09 and 10; training is
full-batch and deterministic (no seed enters). Peers: ``ahrs`` Madgwick, Mahony, EKF and
complementary, each one's gain chosen on 00-08 from a grid, their conventions checked first on a
noiseless simulated drive whose accelerometer feels gravity only (``peer_convention_check_deg``;
the complementary filter adds body rates to Euler angles, 0.3 deg there). ``rmse_deg_offset_removed`` removes
each drive's mean error (what a constant misalignment costs); ``rmse_deg_uncalibrated`` runs the
hand-set filters on the IMU rows and the truth as given.

EuRoC V1_02_medium: frames of 20 samples (0.1 s); the IMU frame turned so that its x axis (up on
this drone) is z (a fixed axis permutation, for Euler angles away from gimbal lock), truth from
the motion capture's ``q_RS``; quarters 1-2 train (and tune the peers), 3 selects, 4 tests.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/attitude_real.py [--steps 300]
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

import attitude as sim  # the simulated benchmark's runners (sets jax_enable_x64)
from jbevo.data.imu_stream import group_blocks
from jbevo.data.kitti import imu_to_rectified_camera
from jbevo.data.kitti_frames import body_from_camera_rotation
from jbevo.data.synthetic.imu import NOISELESS, simulate_imu
from jbevo.data.synthetic.trajectories import procedural_drive
from jbevo.files import write_json_atomic
from jbevo.geometry.euler import euler_zyx, rotation_zyx
from jbevo.inertial import calibration as cal
from jbevo.inertial.attitude_filter import AttitudeFilter, integrate_gyro
from jbevo.inertial.kinematics import fill_missing, tilt_measurements
from jbevo.inertial.kitti_imu import FRAME_STEP_S, RECORDING_DAYS, SAMPLES_PER_FRAME, calibrated_drive, calibration_drive
from jbevo.inertial.speed_aided import SpeedAidedAttitude

FIT = ["00", "01", "02", "04", "05", "06", "07"]
VALIDATION = ["08"]
TEST = ["09", "10"]
SAMPLES = SAMPLES_PER_FRAME

# ---------------------------------------------------------------------------------------- data


def drive_data(pitch_roll, gyro, accel, velocity) -> dict:
    """A drive in the form the runners take: blocks 1..N-1 and the truth at frames 0..N-1."""
    return {
        "gyro": gyro[1:],
        "accel": accel[1:],
        "velocity": velocity[1:],
        "truth": pitch_roll[1:],
        "initial": pitch_roll[0],
        "truth_all": pitch_roll,
    }


def planar_velocity(poses: np.ndarray, step: float, noise: float, seed: int) -> np.ndarray:
    """The odometry stand-in: the truth's world velocity (central differences) in the heading
    frame, plus N(0, noise) per axis and frame."""
    p = poses[:, :3, 3]
    v = np.gradient(p, step, axis=0)
    yaw = euler_zyx(poses[:, :3, :3])[:, 0]
    c, s = np.cos(yaw), np.sin(yaw)
    vb = np.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]], -1)
    return vb + np.random.default_rng(seed).normal(0, noise, vb.shape)


def kitti_folders(root: Path) -> tuple[Path, Path]:
    return root / "kitti_odom" / "gt_poses", root / "kitti_odom" / "imu"


def calibrated(root: Path, c: cal.ImuCalibration, name: str, speed_noise: float) -> tuple[dict, float]:
    d = calibrated_drive(*kitti_folders(root), name, calibration=c)
    pr = euler_zyx(d.body_poses[:, :3, :3])[:, 1:3]
    v = planar_velocity(d.body_poses, FRAME_STEP_S, speed_noise, 100 + int(name))
    return drive_data(pr, d.gyro, d.accel, v), d.gravity.tilt_deg


def uncalibrated(drive: cal.CalibrationDrive, name: str, speed_noise: float) -> dict:
    _, gyro, accel = group_blocks(drive.imu, drive.frame_times)
    pr = euler_zyx(drive.body_poses[:, :3, :3])[:, 1:3]
    v = planar_velocity(drive.body_poses, FRAME_STEP_S, speed_noise, 100 + int(name))
    return drive_data(pr, gyro, accel, v)


# ------------------------------------------------------------------------------------- methods


def gyro_only(s: dict, dt: float):
    def step(x, g):
        x = integrate_gyro(x, fill_missing(g), dt)
        return x, x

    return jax.lax.scan(step, jnp.asarray(s["initial"]), jnp.asarray(s["gyro"]))[1]


def scores(estimates: list, seqs: list[dict]) -> tuple[float, float]:
    """RMSE (deg) pooled, and with each drive's mean error removed."""
    errs = [np.asarray(e) - s["truth"] for e, s in zip(estimates, seqs)]
    pooled = np.concatenate(errs)
    centred = np.concatenate([e - e.mean(0) for e in errs])
    return float(np.degrees(np.sqrt(np.mean(pooled**2)))), float(np.degrees(np.sqrt(np.mean(centred**2))))


def fit_selected(f, loss, data, validate, steps: int, lr: float, every: int = 25):
    """Adam on ``loss(f, data)``; every ``every`` steps the validation RMSE ``validate(f)`` (deg);
    returns the best-validating parameters (the hand-set ones are step 0's candidate)."""
    step, state = sim.adam_step(loss, lr, f)
    best, best_val, best_step, history = f, validate(f), 0, []
    for i in range(1, steps + 1):
        f, state, value = step(f, state, data)
        if i % every == 0 or i == steps:
            val = validate(f)
            history.append((i, float(np.degrees(np.sqrt(value))), val))
            print(f"  step {i:4d}  train {history[-1][1]:.4f}  validation {val:.4f} deg", flush=True)
            if val < best_val:
                best, best_val, best_step = f, val, i
    return best, {"selected_step": best_step, "validation_rmse_deg": best_val, "history": history}


def dukf_loss(compensated: bool):
    def loss(f, data):
        est = jax.vmap(lambda g, a, i, c: f(g, a, i, c if compensated else None))(
            data["gyro"], data["accel"], data["initial"], data["velocity"]
        )
        return jnp.mean((est - data["truth"]) ** 2)

    return loss


def speed_aided_loss(f, data):
    est = jax.vmap(lambda g, a, i, v: sim.run_speed_aided(f, g, a, i, v))(
        data["gyro"], data["accel"], data["initial"], data["velocity"]
    )
    return jnp.mean((est - data["truth"]) ** 2)


def as_jnp(s: dict) -> dict:
    return {k: jnp.asarray(np.nan_to_num(v) if k == "velocity" else v) for k, v in s.items()}


def jbevo_methods(
    train: list[dict], val: list[dict], test: list[dict], dt: float, args, window: int, with_velocity: bool
) -> dict:
    """Every jbevo row on ``test`` (learned ones trained on ``train``, selected on ``val``)."""
    run_dukf = eqx.filter_jit(lambda f, s, c: f(s["gyro"], s["accel"], s["initial"], s["velocity"] if c else None))
    run_sa = eqx.filter_jit(lambda f, s: sim.run_speed_aided(f, s["gyro"], s["accel"], s["initial"], s["velocity"]))
    run_sa_smoothed = eqx.filter_jit(
        lambda f, s: sim.run_speed_aided_smoothed(f, s["gyro"], s["accel"], s["initial"], s["velocity"])
    )
    test_j, val_j = [as_jnp(s) for s in test], [as_jnp(s) for s in val]
    data = sim.windows(train, window)
    out, selection = {}, {}
    out["accel_only"] = scores([tilt_measurements(jnp.asarray(s["accel"])) for s in test], test)
    out["gyro_only"] = scores([jax.jit(gyro_only, static_argnums=1)(s, dt) for s in test_j], test)
    kinds = [("dukf", False, False), ("dukf_gyro_bias", True, False)]
    if with_velocity:
        kinds.append(("motion_compensated", True, True))
    for name, bias, comp in kinds:
        f0 = AttitudeFilter.create(dt=dt, gyro_bias=bias)
        out[f"{name}_handset"] = scores([run_dukf(f0, s, comp) for s in test_j], test)
        print(f"training {name}")
        f, selection[name] = fit_selected(
            f0,
            dukf_loss(comp),
            data,
            lambda f, comp=comp: scores([run_dukf(f, s, comp) for s in val_j], val)[0],
            args.steps,
            args.lr,
        )
        out[f"{name}_learned"] = scores([run_dukf(f, s, comp) for s in test_j], test)
    if with_velocity:
        sa0 = SpeedAidedAttitude.create(dt=dt)
        out["speed_aided_handset"] = scores([run_sa(sa0, s) for s in test_j], test)
        print("training speed_aided")
        sa, selection["speed_aided"] = fit_selected(
            sa0, speed_aided_loss, data, lambda f: scores([run_sa(f, s) for s in val_j], val)[0], args.steps, args.lr
        )
        out["speed_aided_learned"] = scores([run_sa(sa, s) for s in test_j], test)
        # Offline: the RTS smoother over the same filters' beliefs (noise as trained for filtering).
        out["speed_aided_smoothed_handset"] = scores([run_sa_smoothed(sa0, s) for s in test_j], test)
        out["speed_aided_smoothed_learned"] = scores([run_sa_smoothed(sa, s) for s in test_j], test)
    return {"scores": out, "selection": selection}


# --------------------------------------------------------------------------------------- peers

PEER_GRIDS = {
    "madgwick": [0.0003, 0.001, 0.003, 0.01, 0.03, 0.1],
    "mahony": [0.003, 0.01, 0.03, 0.1, 0.3, 1.0],
    "ekf": [0.03, 0.1, 0.3, 1.0, 3.0, 10.0],
    "complementary": [0.9, 0.97, 0.99, 0.997, 0.999, 0.9997],
}


def run_peer(name: str, gain: float, s: dict, rate: float) -> np.ndarray:
    """An ``ahrs`` filter over a drive's samples from the true initial attitude: ``(pitch, roll)``
    at each frame's last sample. The gain: Madgwick's beta, Mahony's k_P (k_I = k_P / 10), the
    EKF's accelerometer noise variance (gyro 0.3^2, as the package's default), the complementary
    filter's gyro weight."""
    from ahrs.filters import EKF, Complementary, Madgwick, Mahony

    gyro = np.asarray(jax.vmap(fill_missing)(jnp.asarray(s["gyro"]))).reshape(-1, 3)
    accel = np.asarray(jax.vmap(fill_missing)(jnp.asarray(s["accel"]))).reshape(-1, 3)
    pitch, roll = s["initial"]
    q0 = Rotation.from_matrix(rotation_zyx(np.array([[0.0, pitch, roll]]))[0]).as_quat()[[3, 0, 1, 2]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if name == "complementary":
            w = Complementary(gyr=gyro, acc=accel, frequency=rate, gain=gain, w0=np.array([roll, pitch, 0.0])).W
            euler = np.stack([w[:, 1], w[:, 0]], -1)
        else:
            if name == "madgwick":
                q = Madgwick(gyr=gyro, acc=accel, frequency=rate, gain=gain, q0=q0).Q
            elif name == "mahony":
                q = Mahony(gyr=gyro, acc=accel, frequency=rate, k_P=gain, k_I=gain / 10, q0=q0).Q
            else:
                # ahrs's "NED" reference takes gravity's reading as +z, as jbevo's specific force (checked).
                q = EKF(gyr=gyro, acc=accel, frequency=rate, frame="NED", q0=q0, noises=[0.3**2, gain, 0.8**2]).Q
            euler = euler_zyx(Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix())[:, 1:3]
    per_frame = gyro.shape[0] // len(s["gyro"])
    return euler[per_frame - 1 :: per_frame]


def peers(tune: list[dict], test: list[dict], rate: float) -> dict:
    out = {}
    for name, grid in PEER_GRIDS.items():
        tuned = [scores([run_peer(name, g, s, rate) for s in tune], tune)[0] for g in grid]
        gain = grid[int(np.argmin(tuned))]
        rmse, centred = scores([run_peer(name, gain, s, rate) for s in test], test)
        out[name] = {
            "gain": gain,
            "tuning_rmse_deg": dict(zip(map(str, grid), tuned)),
            "rmse_deg": rmse,
            "rmse_deg_offset_removed": centred,
        }
        print(f"  {name:14s} gain {gain:<8g} test {rmse:.4f} deg")
    return out


def convention_check() -> dict:
    """Each peer on a noiseless simulated drive whose accelerometer feels gravity only (100 Hz,
    10 samples per frame, the middle gain of its grid): the RMSE (deg) of its pitch and roll,
    which a convention error (axes, signs, quaternion order, reference frame) makes large."""
    t, body = procedural_drive(3, 600)
    d = simulate_imu(t, body, rate_hz=100.0, noise=NOISELESS)
    gravity_only = np.einsum("nji,j->ni", rotation_zyx(d.euler), np.array([0.0, 0.0, 9.80665]))
    n = len(t) - 1
    nan = np.full((1, SAMPLES, 3), np.nan)
    s = drive_data(
        d.frame_euler[:, 1:3],
        np.concatenate([nan, d.gyro[: n * SAMPLES].reshape(n, SAMPLES, 3)]),
        np.concatenate([nan, gravity_only[: n * SAMPLES].reshape(n, SAMPLES, 3)]),
        np.zeros((len(t), 2)),
    )
    out = {name: scores([run_peer(name, grid[len(grid) // 2], s, 100.0)], [s])[0] for name, grid in PEER_GRIDS.items()}
    for name, v in out.items():
        if v > 1.0:
            raise SystemExit(f"{name}: {v:.2f} deg on a noiseless drive: a convention does not match")
    return out


# -------------------------------------------------------------------------------------- EuRoC

_R_B_S = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # EuRoC IMU x (up) -> z


def euroc(root: Path) -> tuple[list[dict], float]:
    """The four quarters of EuRoC V1_02_medium as drives (20-sample frames at 200 Hz)."""
    base = root / "realdata" / "euroc_V1_02_medium_imu_gt" / "mav0"
    imu = np.loadtxt(base / "imu0" / "data.csv", delimiter=",", comments="#")
    gt = np.loadtxt(base / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#")
    t_imu, t_gt = (imu[:, 0] - gt[0, 0]) * 1e-9, (gt[:, 0] - gt[0, 0]) * 1e-9
    per = 20
    start = np.searchsorted(t_imu, 0.0)
    n = (np.searchsorted(t_imu, t_gt[-1]) - start) // per
    rows = slice(start, start + n * per)
    gyro = (imu[rows, 1:4] @ _R_B_S.T).reshape(n, per, 3)
    accel = (imu[rows, 4:7] @ _R_B_S.T).reshape(n, per, 3)
    frame_t = t_imu[rows].reshape(n, per)[:, -1]
    r_rs = Slerp(t_gt, Rotation.from_quat(gt[:, [5, 6, 7, 4]]))(frame_t).as_matrix()
    pr = euler_zyx(r_rs @ _R_B_S.T)[:, 1:3]
    quarters = []
    for q in range(4):
        sl = slice(q * n // 4, (q + 1) * n // 4)
        quarters.append(drive_data(pr[sl], gyro[sl], accel[sl], np.zeros((sl.stop - sl.start, 2))))
    return quarters, 1.0 / 200.0


# -------------------------------------------------------------------------------- diagnostics


def diagnostics(test: list[dict], dt: float, c: cal.ImuCalibration, args) -> dict:
    """What bounds the scores on 09 and 10 (not results):

    * ``gyro_only_short_windows_deg``: gyro integration alone over windows of 100 and 300 frames
      (10 and 30 s) from the true attitude: the gyro's own drift, without the calibration's
      constant errors;
    * ``truth_and_gyro_noise_deg_per_frame``: the RMS per frame and axis of the calibrated gyro
      against the truth's rotation (the truth's own noise and the gyro's, together; calibration of 09's day);
    * ``calibration_std_deg``: the jackknife spread of the mounting's tilt (x, y): a constant
      error no filter here can see (the levelling's: ``calibration.world_tilt_std_deg``);
    * ``speed_aided_fitted_on_test_deg``: the speed-aided filter with Q, R fitted on 09 and 10
      themselves (about the best its structure reaches there);
    * ``accel_bias_tilt_spread_deg`` (added by ``main``): the tilt that the drive-to-drive spread
      of the accelerometer's bias fakes (x: pitch, y: roll)."""
    out: dict = {}
    for length in (100, 300):
        w = sim.windows(test, length)
        est = jax.vmap(lambda g, i: gyro_only({"gyro": g, "initial": i}, dt))(w["gyro"], w["initial"])
        out.setdefault("gyro_only_short_windows_deg", {})[str(length)] = float(
            np.degrees(np.sqrt(np.mean((np.asarray(est) - np.asarray(w["truth"])) ** 2)))
        )
    out["truth_and_gyro_noise_deg_per_frame"] = c.gyro_residual_deg
    std = c.std
    out["calibration_std_deg"] = {
        "mounting_x_y": [] if std is None else std.rotation_deg[:2].tolist(),
    }
    test_j = [as_jnp(s) for s in test]
    run_sa = eqx.filter_jit(lambda f, s: sim.run_speed_aided(f, s["gyro"], s["accel"], s["initial"], s["velocity"]))

    def loss(f, seqs):
        return sum(jnp.sum((run_sa(f, s) - s["truth"]) ** 2) for s in seqs) / sum(len(s["truth"]) for s in seqs)

    print("diagnostic: the speed-aided filter fitted on 09 and 10 themselves")
    f, _ = sim.fit(SpeedAidedAttitude.create(dt=dt), loss, test_j, args.steps, args.lr)
    out["speed_aided_fitted_on_test_deg"] = scores([run_sa(f, s) for s in test_j], test)[0]
    return out


# ------------------------------------------------------------------------------------ IMU noise

LONG_DRIVE_FRAMES = 1000
ALLAN_TAUS = np.logspace(np.log10(FRAME_STEP_S), 2.5, 24)


def standstill_segments(drive: cal.CalibrationDrive, min_frames: int = 10, max_speed: float = 0.05) -> list[np.ndarray]:
    """The raw IMU samples of each stop of at least ``min_frames`` frames (truth speed below
    ``max_speed`` m/s), as ``(M, 6)`` arrays (gyro, accel)."""
    p = drive.body_poses[:, :3, 3]
    still = np.linalg.norm(np.diff(p, axis=0), axis=-1) / FRAME_STEP_S < max_speed
    out, start = [], None
    for k, s in enumerate(np.append(still, False)):
        if s and start is None:
            start = k
        elif not s and start is not None:
            if k - start >= min_frames:
                rows = slice(SAMPLES * start, SAMPLES * k)
                out.append(np.concatenate([drive.imu.gyro[rows], drive.imu.accel[rows]], -1))
            start = None
    return out


def imu_noise(drives: list[cal.CalibrationDrive], calibrations: list[cal.ImuCalibration], per_drive: dict) -> dict:
    """The KITTI IMU's noise, as far as this data shows it: white-noise densities from the stops
    (the sensor with the engine's vibration); the Allan deviation of the gyro's residual against
    the truth (pooled over drives, weighted by length) and its noise-model fit, whose white term
    is the truth's own noise more than the gyro's (an upper bound); the gyro's bias random walk
    bounded by the smallest ``adev(tau) sqrt(3 / tau)`` over tau >= 10 s (no rising branch shows
    up to 100 s); the turn-on biases as the spread of the per-drive bias estimates of the drives with
    at least ``LONG_DRIVE_FRAMES`` frames."""
    from jbevo.data.synthetic.imu import ADIS16448
    from jbevo.inertial.noise_fit import allan_deviation, fit_allan, standstill_density

    segments = [s for d in drives for s in standstill_segments(d)]
    density = standstill_density(segments, FRAME_STEP_S / SAMPLES)
    sq, weight = np.zeros((len(ALLAN_TAUS), 3)), np.zeros((len(ALLAN_TAUS), 1))
    for d, c in zip(drives, calibrations):
        _, rates = cal.gyro_residual_rates(d, c)
        a = allan_deviation(rates, FRAME_STEP_S, ALLAN_TAUS)
        ok = np.isfinite(a)
        sq += np.where(ok, a**2, 0.0) * len(rates)
        weight += ok[:, :1] * len(rates)
    adev = np.sqrt(sq / np.maximum(weight, 1))
    adev[weight[:, 0] == 0] = np.nan
    long = (ALLAN_TAUS >= 10.0) & np.isfinite(adev[:, 0])
    walk_bound = np.min(adev[long] * np.sqrt(3.0 / ALLAN_TAUS[long, None]), 0)
    # The per-drive biases of drives long enough to hold them (04's 271 frames do not: its
    # accelerometer bias is confounded with the world's tilt over so short a drive).
    long_drives = [v for d, v in zip(drives, per_drive.values()) if len(d.frame_times) >= LONG_DRIVE_FRAMES]
    gyro_biases = np.radians([v["gyro_bias_deg_s"] for v in long_drives])
    accel_biases = np.array([v["accel_bias_m_s2"] for v in long_drives])
    return {
        "standstill_segments": len(segments),
        "standstill_seconds": float(sum(len(s) for s in segments) * FRAME_STEP_S / SAMPLES),
        "gyro_noise_density_rad_s_sqrt_hz": density[:3].tolist(),
        "accel_noise_density_m_s2_sqrt_hz": density[3:].tolist(),
        "gyro_random_walk_bound_rad_s2_sqrt_hz": walk_bound.tolist(),
        "gyro_bias_spread_rad_s": gyro_biases.std(0).tolist(),
        "accel_bias_spread_m_s2": accel_biases.std(0).tolist(),
        "gyro_residual_allan": {"tau_s": ALLAN_TAUS.tolist(), "adev_rad_s": adev.tolist()},
        "gyro_residual_fit": {k: v.tolist() for k, v in fit_allan(ALLAN_TAUS, adev).items()},
        "adis16448": {
            "gyro_noise_density_rad_s_sqrt_hz": ADIS16448.gyro_noise_density,
            "gyro_random_walk_rad_s2_sqrt_hz": ADIS16448.gyro_random_walk,
            "accel_noise_density_m_s2_sqrt_hz": ADIS16448.accel_noise_density,
            "accel_random_walk_m_s3_sqrt_hz": ADIS16448.accel_random_walk,
        },
    }


# ---------------------------------------------------------------------------------------- main


def split(results: dict) -> tuple[dict, dict]:
    return {k: v[0] for k, v in results.items()}, {k: v[1] for k, v in results.items()}


def main() -> None:
    parser = sim.options(__doc__ or "", 600, "attitude_real.json")
    parser.add_argument("--euroc-window", type=int, default=100)
    args = parser.parse_args()
    sim.reference_data(args)
    t0 = time.time()
    results: dict = {"peer_convention_check_deg": convention_check()}

    names = FIT + VALIDATION + TEST
    drives = {n: calibration_drive(*kitti_folders(args.data), n) for n in names}
    published = body_from_camera_rotation(
        imu_to_rectified_camera(args.data / "realdata" / "kitti_raw_2011_09_26_drive_0001_oxts" / "calib")[:3, :3]
    )
    per_drive = {n: cal.calibrate([drives[n]], groups=0).summary() for n in names}
    calibrations, per_day = {}, {}
    for day, members in RECORDING_DAYS.items():
        fitted_on = [n for n in members if n in FIT + VALIDATION]
        print(f"calibrating the IMU of {day} on {' '.join(fitted_on)}")
        c = cal.calibrate([drives[n] for n in fitted_on])
        calibrations.update({n: c for n in members})
        per_day[day] = c.summary() | {
            "fitted_on": fitted_on,
            "estimate_minus_published_deg": np.degrees(
                Rotation.from_matrix(c.rotation_body_imu @ published.T).as_rotvec()
            ).tolist(),
        }
        print(f"  mounting {c.rotation_deg.round(3)} deg, offset {c.time_offset_s:.4f} s, gyro scale {c.gyro_scale:.5f}")
    data, tilt = {}, {}
    for n in names:
        data[n], tilt[n] = calibrated(args.data, calibrations[n], n, args.speed_noise)
    dt = FRAME_STEP_S / SAMPLES
    results["calibration"] = {
        "per_day": per_day,
        "per_drive": per_drive,
        "world_tilt_deg": tilt,
        "world_tilt_std_deg": {n: cal.gravity_up(drives[n], calibrations[n]).tilt_std_deg for n in names},
        "published_2011_09_26_rotation_body_imu_deg": np.degrees(Rotation.from_matrix(published).as_rotvec()).tolist(),
    }

    train, val, test = [data[n] for n in FIT], [data[n] for n in VALIDATION], [data[n] for n in TEST]
    kitti = jbevo_methods(train, val, test, dt, args, args.window, with_velocity=True)
    results["rmse_deg"], results["rmse_deg_offset_removed"] = split(kitti["scores"])
    results["selection"] = kitti["selection"]
    test_calibration = calibrations[TEST[0]]
    results["diagnostic"] = diagnostics(test, dt, test_calibration, args)
    results["imu_noise"] = imu_noise([drives[n] for n in names], [calibrations[n] for n in names], per_drive)
    # The tilt an accelerometer bias fakes (pitch -b_x / g, roll b_y / g) is body-fixed like
    # gravity's: the spread of the per-drive estimates is what one pooled bias leaves per drive.
    spread = np.array(results["imu_noise"]["accel_bias_spread_m_s2"][:2])
    results["diagnostic"]["accel_bias_tilt_spread_deg"] = np.degrees(spread / 9.80665).tolist()
    print("ahrs peers, gains chosen on 00-08")
    results["peers"] = peers(train + val, test, 1.0 / dt)

    raw = [uncalibrated(drives[n], n, args.speed_noise) for n in TEST]
    raw_j = [as_jnp(s) for s in raw]
    dt_raw = FRAME_STEP_S / SAMPLES
    run_dukf = eqx.filter_jit(lambda f, s: f(s["gyro"], s["accel"], s["initial"]))
    run_sa = eqx.filter_jit(lambda f, s: sim.run_speed_aided(f, s["gyro"], s["accel"], s["initial"], s["velocity"]))
    results["rmse_deg_uncalibrated"] = {
        "accel_only": scores([tilt_measurements(jnp.asarray(s["accel"])) for s in raw], raw)[0],
        "gyro_only": scores([jax.jit(gyro_only, static_argnums=1)(s, dt_raw) for s in raw_j], raw)[0],
        "dukf_handset": scores([run_dukf(AttitudeFilter.create(dt=dt_raw), s) for s in raw_j], raw)[0],
        "speed_aided_handset": scores([run_sa(SpeedAidedAttitude.create(dt=dt_raw), s) for s in raw_j], raw)[0],
    }

    print("EuRoC V1_02_medium: quarters 1-2 train, 3 selects, 4 tests")
    quarters, dt_e = euroc(args.data)
    e = jbevo_methods(quarters[:2], [quarters[2]], [quarters[3]], dt_e, args, args.euroc_window, with_velocity=False)
    results["euroc"] = {
        "rmse_deg": split(e["scores"])[0],
        "selection": e["selection"],
        "peers": peers(quarters[:2], [quarters[3]], 1.0 / dt_e),
    }
    results["config"] = {
        "fit": FIT,
        "validation": VALIDATION,
        "test": TEST,
        "frame_step_s": FRAME_STEP_S,
        "samples_per_frame": SAMPLES,
        "window": args.window,
        "euroc_window": args.euroc_window,
        "steps": args.steps,
        "lr": args.lr,
        "speed_noise_m_s": args.speed_noise,
        "seconds": time.time() - t0,
    }
    write_json_atomic(args.out, results)
    for k in ("rmse_deg", "rmse_deg_offset_removed"):
        for m, v in results[k].items():
            print(f"{k:26s} {m:30s} {v:8.4f}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
