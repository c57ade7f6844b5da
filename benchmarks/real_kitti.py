"""BEVO on real camera frames: the real KITTI runs in the reference data (``realdata/``: the first
51 frames of sequence 06, the first 160 of 07, grey camera 0) with their real IMU, against their
ground truth, and two peers on the same frames.

Data. Each run is read as shipped (:func:`jbevo.data.kitti.read_run`) and, for every row but the
``uncalibrated`` ones, with its sequence's IMU calibrated and its truth levelled against gravity
(:func:`jbevo.inertial.kitti_imu.calibrated_sequence`). The calibration (mounting, time offset,
gyro scale and biases) is fitted on the recording day's drives 04, 05 and 08 only, so no scored
drive enters it. KITTI's own truth is relative to the first camera pose; the levelled truth's
pitch and roll are against gravity, the reference every pitch/roll figure is taken against.

Rows (``VARIANTS``; hand-set unless named otherwise). ``BEVO`` is the model as the synthetic
experiments run it (:meth:`jbevo.models.Bevo.create`, the KITTI-size grid, filter attitude), with
and without bands, on the uncalibrated and the calibrated IMU; ``street`` is
:func:`jbevo.models.presets.street_model` (road view: camera against the road and road corridor;
the gyro's turn fused with DPC's; where named, robust bands engaged from 1 m per frame that
measure the road's tilt) with the filter's, the true (levelled) or a zero attitude; the band
rows also without the road tilt (the slope then corrects the pitch against gravity), engaged
from 0.5 m per frame or at any speed, and with keyframes (the band pair is the current BEV and
the last one at which the bands engaged; they engage once the travel since reaches 1 m),
projected on a level road (``level road``: the BEV's pitch the bands' tilt alone, its roll zero;
:attr:`jbevo.models.road_tilt.RoadTilt.level`), and on the run with the IMU blocks that lie on
the published file's dropout lines marked missing (``IMU dropouts missing``:
:func:`jbevo.data.kitti.without_dropouts`, rows taken at the calibration's time offset; the
preset's attitude then widens through the blocks left without any sample by
:data:`jbevo.models.presets.STREET_GAP_RATE_STD`, or, ``attitude not widened``, only holds). Learned rows fit on one half of a run and are scored on the other
(both directions; ``--seeds`` seeds of the window order, mean and standard deviation):
``street, calibrated`` learns the road view's pitch, roll and height (3 numbers),
``street, learned`` the whole road view, the yaw fusion and DPC's parameters (11),
``street + robust bands, learned`` those, the bands' two and the road tilt's walk (14). Each fit
holds out the last third of its training half (``VALIDATION_SHARE``) and keeps, among the
starting (hand-set) parameters and every ``--every`` of its ``--steps`` Adam steps, the checkpoint
with the lowest final error on those frames (run from their first frame's true state); no frame
of the scored half chooses anything. ``checkpoint_selection[<run>][<variant>][trained on the
<half>]``: per seed, the chosen ``step`` and the validation error at each checkpoint.
Peers on the same frames: ``cv2.phaseCorrelate`` between the same BEV pairs as the
hand-set street model's (translation only; the turn from the gyro, as the street model's
fusion mostly takes it), and a monocular essential-matrix VO (ORB features,
``cv2.findEssentialMat`` with RANSAC, ``cv2.recoverPose``) whose unit steps get their length
either from the truth at every frame (``oracle scale``) or from the first true step alone.

Metrics, per run and per half (every model runs over the whole run from the true state at frame
0; a half is scored on its own increments, composed from the true pose at its start):
``motion_cm`` (RMSE of the per-frame planar step), ``distance_ratio`` (estimated path length
over true), ``yaw_deg`` (RMSE of the per-frame turn), ``final_pct`` (final position error over
the distance travelled), ``pitch_roll_max_deg``, ``pitch_roll_worst_frame`` (the run's frame of that maximum) and
``pitch_roll_rmse_deg`` (the attitude the BEVs were projected with against the levelled truth).
``imu_interpolated_frames[<run>]``: the run's frames whose published IMU sample is a straight line
over an OXTS dropout (:func:`jbevo.data.kitti.interpolated_frames`);
``training_tilt_rate_rms_deg_s``: the RMS of the published roll and pitch rates over the KITTI
training drives that no run here comes from (the rate ``STREET_GAP_RATE_STD`` assumes);
``gyro_alone_drift_deg[<run>]["from_frame"][k]``: the largest pitch/roll error over the next
``frames`` frames of the calibrated gyro integrated alone from the truth at frame ``k``. Keys: ``runs[<run>][<variant>][<metric>]``
with ``<run>`` one of ``06``, ``06 first half``, ``06 second half`` and likewise for 07.
``frames_per_s[<run>][<variant>]``: the ``TIMED`` rows run once more, compiled (the same process and
frames). Figures: ``benchmarks/results/real_kitti_<run>.png``.

    JBEVO_REFERENCE_DATA=../shared/data python benchmarks/real_kitti.py [--steps 40] [--seeds 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import cv2
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from jbevo.data import kitti
from jbevo.data import sequence as sq
from jbevo.data.kitti_frames import body_from_camera_rotation
from jbevo.data.splits import KITTI_TRAIN
from jbevo.eval.plots import trajectory_top_view
from jbevo.files import write_json_atomic
from jbevo.geometry.angles import wrap_angle
from jbevo.geometry.se2 import se2_compose
from jbevo.inertial import kitti_imu
from jbevo.inertial.attitude_filter import integrate_gyro
from jbevo.inertial.kinematics import fill_missing, gyro_yaw_increment
from jbevo.models import Bevo, motion_loss, relative_motion
from jbevo.models.presets import STREET_GRID, street_model
from jbevo.models.runners import run_bevo
from jbevo.training.loop import make_step
from jbevo.vision.bev import bev_increment

RUNS = {"06": "kitti_odometry_06_first51", "07": "kitti_odometry_07_first160"}
#: The IMU's calibration: the recording day's training drives, less the scored ones (04, 05, 08).
CALIBRATION_DAY = "2011_09_30"
HALVES = ("first half", "second half")
RESULTS = Path(__file__).parent / "results"
#: The share of a training half held out at its end to choose the learned rows' checkpoint.
VALIDATION_SHARE = 1 / 3
#: Adam steps between the checkpoints that the held-out frames choose among (step 0, the
#: hand-set parameters, is one of them).
CHECK_EVERY = 10
#: Rows timed once more after compiling (``frames_per_s[<run>][<variant>]``, this machine).
TIMED = ("street + robust bands", "street + robust bands, keyframes")


# ------------------------------------------------------------------ data


def run_calibration(root: Path):
    """The IMU calibration of the runs' recording day, fitted without the runs' drives (cached
    per process by :func:`jbevo.inertial.kitti_imu.day_calibration`)."""
    poses, imu = root / "kitti_odom" / "gt_poses", root / "kitti_odom" / "imu"
    return kitti_imu.day_calibration(str(poses), str(imu), CALIBRATION_DAY, exclude=tuple(RUNS))


def load_runs(root: Path) -> dict[str, tuple[sq.Sequence, sq.Sequence]]:
    """Each run as shipped and with its calibrated IMU and levelled truth."""
    poses, imu = root / "kitti_odom" / "gt_poses", root / "kitti_odom" / "imu"
    calibration = run_calibration(root)
    return {
        name: kitti_imu.read_calibrated_run(root / "realdata" / folder, poses, imu, name, calibration)
        for name, folder in RUNS.items()
    }


def half_frames(n: int, half: str) -> tuple[int, int]:
    """Frames ``[start, stop)`` of a half (the middle frame belongs to both: each half's first
    increment ends at its second frame)."""
    mid = n // 2
    return (0, mid + 1) if half == "first half" else (mid, n)


# ------------------------------------------------------------------ metrics


def compose(start: np.ndarray, increments: np.ndarray) -> np.ndarray:
    """The planar poses ``start`` and after each of ``increments`` (body frame of the pose before)."""
    poses = [np.asarray(start, float)]
    for inc in np.asarray(increments, float):
        poses.append(np.asarray(se2_compose(jnp.asarray(poses[-1]), jnp.asarray(inc)), float))
    return np.stack(poses)


def scores(increments: np.ndarray, pitch_roll: np.ndarray | None, seq: sq.Sequence, start: int, stop: int) -> dict:
    """The metrics of estimated ``increments`` (T, 3; row t from frame t - 1 to t) over frames
    ``[start, stop)`` against ``seq``'s truth (its pitch and roll: the levelled truth's)."""
    truth = np.asarray(seq.planar, float)
    true_inc = np.asarray(relative_motion(seq), float)[start + 1 : stop]
    est = np.asarray(increments, float)[start + 1 : stop]
    err = est - true_inc
    err[:, 2] = np.asarray(wrap_angle(err[:, 2]))
    pose = compose(truth[start], est)[-1]
    distance = float(np.sum(np.linalg.norm(true_inc[:, :2], axis=1)))
    out = {
        "frames": stop - start,
        "distance_m": distance,
        "motion_cm": 100 * float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, 1)))),
        "distance_ratio": float(np.sum(np.linalg.norm(est[:, :2], axis=1))) / distance,
        "yaw_deg": float(np.degrees(np.sqrt(np.mean(err[:, 2] ** 2)))),
        "final_pct": 100 * float(np.linalg.norm(pose[:2] - truth[stop - 1, :2])) / distance,
    }
    if pitch_roll is not None:
        pr_err = np.degrees(np.asarray(pitch_roll, float)[start:stop] - np.asarray(seq.pitch_roll, float)[start:stop])
        out["pitch_roll_max_deg"] = float(np.abs(pr_err).max())
        out["pitch_roll_worst_frame"] = start + int(np.abs(pr_err).max(axis=1).argmax())
        out["pitch_roll_rmse_deg"] = float(np.sqrt(np.mean(pr_err**2)))
    return out


#: Frames over which :func:`gyro_alone_drift` integrates the calibrated gyro from the truth (1 s).
GYRO_WINDOW = 10


def gyro_alone_drift(seq: sq.Sequence, frames: int = GYRO_WINDOW) -> list[float]:
    """Per start frame ``k``: the largest pitch/roll error (deg) over frames ``k + 1 .. k + frames``
    of the calibrated gyro integrated alone from the truth's attitude at ``k``. Where the IMU
    and the truth agree it stays at hundredths of a degree; where they disagree, no filter that
    follows the gyro can match the truth."""
    step = jax.jit(lambda pr, gyro: integrate_gyro(pr, fill_missing(gyro), seq.imu_dt))
    truth = np.asarray(seq.pitch_roll, float)
    gyro = jnp.asarray(seq.gyro)
    out = []
    for k in range(seq.num_frames - frames):
        pr, worst = jnp.asarray(truth[k]), 0.0
        for t in range(k + 1, k + frames + 1):
            pr = step(pr, gyro[t])
            worst = max(worst, float(np.degrees(np.abs(np.asarray(pr, float) - truth[t])).max()))
        out.append(worst)
    return out


def segments(increments, pitch_roll, seq: sq.Sequence) -> dict[str, dict]:
    """:func:`scores` over the whole run and over each half."""
    n = seq.num_frames
    out = {"whole": scores(increments, pitch_roll, seq, 0, n)}
    for half in HALVES:
        out[half] = scores(increments, pitch_roll, seq, *half_frames(n, half))
    return out


# ------------------------------------------------------------------ models


#: The data a hand-set row runs on: the run as shipped, with the calibrated IMU and levelled truth,
#: and the latter with the IMU rows on a dropout's straight line marked missing
#: (:func:`jbevo.data.kitti.without_dropouts`, at the calibration's time offset).
SHIPPED, CALIBRATED, DROPOUTS_MISSING = "as shipped", "calibrated", "calibrated, dropouts missing"


def hand_set(imu_dt: float) -> dict[str, tuple[Bevo, str]]:
    """The hand-set rows: label -> (model, the data it runs on: ``SHIPPED``, ``CALIBRATED`` or
    ``DROPOUTS_MISSING``)."""
    plain = Bevo.create(STREET_GRID, imu_dt)
    banded = Bevo.create(STREET_GRID, imu_dt, bands=True)
    street = street_model(imu_dt, bands=False)
    preset = street_model(imu_dt, bands=True)
    return {
        "BEVO, uncalibrated IMU": (plain, SHIPPED),
        "BEVO + bands, uncalibrated IMU": (banded, SHIPPED),
        "BEVO": (plain, CALIBRATED),
        "BEVO + bands": (banded, CALIBRATED),
        "BEVO, true attitude": (dataclasses.replace(plain, attitude_source="truth"), CALIBRATED),
        "street": (street, CALIBRATED),
        "street + robust bands": (preset, CALIBRATED),
        "street + robust bands, IMU dropouts missing": (preset, DROPOUTS_MISSING),
        "street + robust bands, IMU dropouts missing, attitude not widened": (
            dataclasses.replace(preset, attitude=dataclasses.replace(preset.attitude, gap_rate_std=0.0)),
            DROPOUTS_MISSING,
        ),
        "street + robust bands, level road": (street_model(imu_dt, bands=True, level_road=True), CALIBRATED),
        "street + robust bands, no road tilt": (dataclasses.replace(preset, road_tilt=None), CALIBRATED),
        "street + robust bands, from 0.5 m per frame": (street_model(imu_dt, bands=True, bands_min_travel=0.5), CALIBRATED),
        "street + robust bands, keyframes": (street_model(imu_dt, bands=True, bands_keyframes=True), CALIBRATED),
        "street + robust bands, at any speed": (street_model(imu_dt, bands=True, bands_min_travel=0.0), CALIBRATED),
        "street + robust bands, at any speed, no road tilt": (
            dataclasses.replace(street_model(imu_dt, bands=True, bands_min_travel=0.0), road_tilt=None),
            CALIBRATED,
        ),
        "street, true attitude": (dataclasses.replace(street, attitude_source="truth"), CALIBRATED),
        "street, zero attitude (no IMU)": (dataclasses.replace(street, attitude_source="zero"), CALIBRATED),
    }


def training_tilt_rate_rms(root: Path) -> float:
    """The RMS (deg/s) of the roll and pitch rates (the published gyro's x and y) over the KITTI
    training drives with an IMU file that no real run here comes from: the rate
    :data:`jbevo.models.presets.STREET_GAP_RATE_STD` assumes through a missing gyro block."""
    poses, imu = root / "kitti_odom" / "gt_poses", root / "kitti_odom" / "imu"
    squares, count = 0.0, 0
    for name in KITTI_TRAIN:
        if name in RUNS or not (imu / f"{name}.mat").is_file():
            continue
        rates = np.degrees(np.asarray(kitti_imu.calibration_drive(poses, imu, name).imu.gyro, float)[:, :2])
        squares, count = squares + float(np.sum(rates**2)), count + rates.size
    return float(np.sqrt(squares / count))


#: Learned rows: label -> (whether the street model has its bands, which of its leaves learn).
LEARNED = {
    "street, calibrated": (False, lambda m: (m.road.pitch, m.road.roll, m.road.log_height_scale)),
    "street, learned": (False, lambda m: (m.road, m.yaw_fusion, m.dpc)),
    "street + robust bands, learned": (True, lambda m: (m.road, m.yaw_fusion, m.dpc, m.bands, m.road_tilt)),
}


def learnable_mask(model: Bevo, select) -> Bevo:
    """A pytree of booleans like ``model``: True on the array leaves of ``select(model)``."""
    mask = jax.tree_util.tree_map(lambda _: False, model)
    chosen = select(model)
    leaves = jax.tree_util.tree_leaves(eqx.filter(chosen, eqx.is_inexact_array))
    return eqx.tree_at(select, mask, replace=jax.tree_util.tree_map(lambda _: True, chosen)) if leaves else mask


class Trainer:
    """Adam on the motion loss over random batches of windows (each from the true state at its
    first frame), on the leaves ``select`` picks only; one compiled step for every fit."""

    def __init__(self, model: Bevo, select, lr: float):
        self.params, static = eqx.partition(model, learnable_mask(model, select))
        self.optimizer = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(lr))
        self.step = make_step(
            static, self.optimizer, lambda m, b: jnp.mean(jax.vmap(lambda s: motion_loss(m(s, warm_start=True), s))(b))
        )
        self.static = static


class Fitted(NamedTuple):
    """A fit's chosen parameters, the step they are from (0: the starting parameters) and the
    validation error at every checkpoint (``{step: error}``; empty without validation)."""

    model: Bevo
    step: int
    validation: dict[int, float]


def fit(
    trainer: Trainer,
    train: sq.Sequence | list[sq.Sequence],
    steps: int,
    seed: int,
    window: int,
    batch: int,
    validate: Callable[[Bevo], float] | None = None,
    every: int = CHECK_EVERY,
) -> Fitted:
    """``steps`` steps (fixed in advance) of ``trainer`` from its starting parameters over
    batches of ``batch`` random ``window``-frame windows of ``train`` (one sequence or several
    with the same camera). With ``validate`` (a model's error on held-out frames), the
    checkpoint with the lowest error among the starting parameters and every ``every`` steps
    is kept; without it, the last."""
    params, step = trainer.params, trainer.step
    parts = [sq.windows(s, window, 1) for s in (train if isinstance(train, list) else [train])]
    windows = jax.tree_util.tree_map(lambda *x: jnp.concatenate(x), *parts)
    rng = np.random.default_rng(seed)
    opt_state = trainer.optimizer.init(params)
    count = windows.frame_times.shape[0]
    curve: dict[int, float] = {}
    best = (np.inf, 0, params)

    def check(k: int, params) -> tuple:
        if validate is None:
            return best
        error = float(validate(eqx.combine(params, trainer.static)))
        curve[k] = error
        # A non-finite validation error never wins.
        return (error, k, params) if np.isfinite(error) and error < best[0] else best

    best = check(0, params)
    for k in range(1, steps + 1):
        idx = rng.choice(count, size=min(batch, count), replace=False)
        params, opt_state, loss = step(params, opt_state, jax.tree_util.tree_map(lambda x, idx=idx: x[idx], windows))
        if not np.isfinite(float(loss)):
            raise RuntimeError("the training loss is not finite")
        if k % every == 0 or k == steps:
            best = check(k, params)
    if validate is None:
        return Fitted(eqx.combine(params, trainer.static), steps, curve)
    return Fitted(eqx.combine(best[2], trainer.static), best[1], curve)


def fit_held_out(trainer: Trainer, train, held_out: sq.Sequence, seed: int, args: argparse.Namespace) -> Fitted:
    """:func:`fit` with the command line's steps, window, batch and checkpoint spacing, the
    checkpoint chosen by :func:`validation_error` on ``held_out``."""
    validate = functools.partial(validation_error, seq=held_out)
    return fit(trainer, train, args.steps, seed, args.window, args.batch, validate, args.every)


def split_training(start: int, stop: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """A training half's frames ``[start, stop)`` as the frames fitted and, at its end, the
    :data:`VALIDATION_SHARE` held out to choose the checkpoint (the two share one frame, as the
    halves do: the validation's first increment ends at its second frame)."""
    cut = stop - max(2, round((stop - start) * VALIDATION_SHARE))
    return (start, cut + 1), (cut, stop)


def validation_error(model: Bevo, seq: sq.Sequence) -> float:
    """The final position error (% of the distance) of ``model`` run over ``seq`` from its
    first frame's true state (a validation window)."""
    out = run_bevo(model, seq, warm_start=True)
    return scores(out.increments, out.pitch_roll, seq, 0, seq.num_frames)["final_pct"]


def learned_parameters(model: Bevo) -> dict:
    """The street model's interpretable numbers."""
    road, fusion = model.road, model.yaw_fusion
    assert road is not None and fusion is not None
    out = {
        "camera_pitch_deg": float(np.degrees(road.pitch)),
        "camera_roll_deg": float(np.degrees(road.roll)),
        "height_scale": float(jnp.exp(road.log_height_scale)),
        "corridor_m": float(jnp.exp(road.log_corridor)),
        "gyro_yaw_weight": float(fusion.gyro_weight),
    }
    if model.road_tilt is not None:
        out["road_tilt_walk_deg_per_sqrt_m"] = float(np.degrees(jnp.exp(model.road_tilt.log_walk_std)))
    return out


# ------------------------------------------------------------------ peers


def phase_correlate_peer(model: Bevo, out, seq: sq.Sequence) -> np.ndarray:
    """Increments from ``cv2.phaseCorrelate`` (with a Hanning window) between the BEVs ``model``
    projected (at the attitude ``out`` reports), the turn from the gyro (bias-free after
    calibration)."""
    bev = jax.jit(jax.vmap(lambda image, pr: model.bev(image, pr, seq.camera)))
    bevs = np.asarray(bev(seq.images, out.pitch_roll), np.float64)
    window = cv2.createHanningWindow(bevs.shape[:0:-1], cv2.CV_64F)
    incs = [np.zeros(3)]
    for t in range(1, seq.num_frames):
        (dx, dy), _ = cv2.phaseCorrelate(bevs[t - 1], bevs[t], window)
        pr = np.asarray(out.pitch_roll[t])
        turn = float(gyro_yaw_increment(seq.gyro[t], pr[0], pr[1], seq.imu_dt))
        incs.append(np.asarray(bev_increment(model.grid, jnp.float32(-turn), jnp.array([dx, dy], jnp.float32))))
    return np.stack(incs)


def essential_matrix_vo(seq: sq.Sequence) -> np.ndarray:
    """Unit-length planar steps ``(dx, dy, dyaw)`` (body frame) of a two-frame monocular VO:
    ORB features, brute-force Hamming matching with the ratio test, the essential matrix with
    RANSAC and ``recoverPose``; NaN where fewer than 8 matches survive."""
    k = np.asarray(seq.camera.intrinsics, np.float64)
    orb = cv2.ORB_create(3000)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    images = np.asarray(seq.images)
    features = [orb.detectAndCompute(image, None) for image in images]
    steps = [np.zeros(3)]
    for t in range(1, len(images)):
        (kp0, d0), (kp1, d1) = features[t - 1], features[t]
        pairs = [p for p in matcher.knnMatch(d0, d1, k=2) if len(p) == 2 and p[0].distance < 0.75 * p[1].distance]
        if len(pairs) < 8:
            steps.append(np.full(3, np.nan))
            continue
        p0 = np.float64([kp0[m[0].queryIdx].pt for m in pairs])
        p1 = np.float64([kp1[m[0].trainIdx].pt for m in pairs])
        e, inliers = cv2.findEssentialMat(p0, p1, k, method=cv2.RANSAC, prob=0.999, threshold=1.0)
        _, r, tvec, _ = cv2.recoverPose(e, p0, p1, k, mask=inliers)
        # x1 = R x0 + t: camera 1 in camera 0 is (R^T, -R^T t); into the body's axes.
        rotation = body_from_camera_rotation(r.T) @ body_from_camera_rotation(np.eye(3)).T
        position = body_from_camera_rotation(-r.T @ tvec.ravel())
        steps.append(
            np.array([*(position[:2] / max(np.linalg.norm(position[:2]), 1e-12)), np.arctan2(rotation[1, 0], rotation[0, 0])])
        )
    return np.stack(steps)


def scaled_steps(unit: np.ndarray, seq: sq.Sequence, oracle: bool) -> np.ndarray:
    """Unit steps scaled by the true step length of every frame (``oracle``) or of the first."""
    truth = np.asarray(seq.planar, float)
    lengths = np.r_[0.0, np.linalg.norm(np.diff(truth[:, :2], axis=0), axis=1)]
    scale = lengths if oracle else np.r_[0.0, np.full(len(truth) - 1, lengths[1])]
    out = unit.copy()
    out[:, :2] *= scale[:, None]
    return np.nan_to_num(out)


# ------------------------------------------------------------------ the benchmark


def summarise(values: list[dict]) -> dict:
    """Mean, standard deviation and the per-seed values of each metric."""
    out = {}
    for key in values[0]:
        v = np.array([x[key] for x in values], float)
        out[key] = float(v.mean())
        out[f"{key}_std"] = float(v.std())
        out[f"{key}_seeds"] = v.tolist()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=40, help="Adam steps per learned model (fixed in advance)")
    parser.add_argument("--every", type=int, default=CHECK_EVERY, help="steps between the checkpoints validation chooses among")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--window", type=int, default=8, help="frames per training window")
    parser.add_argument("--batch", type=int, default=4, help="windows per step")
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--out", type=Path, default=RESULTS / "real_kitti.json")
    args = parser.parse_args()
    root = os.environ.get("JBEVO_REFERENCE_DATA")
    if not root or not (Path(root) / "realdata").is_dir():
        raise SystemExit("set JBEVO_REFERENCE_DATA to the reference data folder (with realdata/ and kitti_odom/)")
    started = time.time()
    runs = load_runs(Path(root))
    imu = Path(root) / "kitti_odom" / "imu"
    # The frames whose published IMU is a straight line over an OXTS dropout (frames the OXTS unit did not record).
    published = {name: kitti.read_kitti_imu(imu / f"{name}.mat", np.asarray(seq.frame_times)) for name, (_, seq) in runs.items()}
    dropouts = {name: np.flatnonzero(kitti.interpolated_frames(stream)) for name, stream in published.items()}
    offset = run_calibration(Path(root)).time_offset_s
    table: dict[str, dict] = {}
    learned_params: dict[str, dict] = {}
    selection: dict[str, dict] = {}
    frames_per_s: dict[str, dict] = {}

    def put(run: str, variant: str, per_segment: dict[str, dict]) -> None:
        for segment, metrics in per_segment.items():
            key = run if segment == "whole" else f"{run} {segment}"
            table.setdefault(key, {})[variant] = metrics

    for name, (raw, seq) in runs.items():
        print(f"run {name}: {seq.num_frames} frames", flush=True)
        trajectories = {}
        street_out = None
        marked = kitti.without_dropouts(seq, kitti.dropout_spans(published[name]), time_offset_s=offset)
        data_for = {SHIPPED: raw, CALIBRATED: seq, DROPOUTS_MISSING: marked}
        for label, (model, data_key) in hand_set(seq.imu_dt).items():
            data = data_for[data_key]
            out = run_bevo(model, data, warm_start=True)
            put(name, label, segments(out.increments, out.pitch_roll, seq))
            if label == "street":
                street_out = out
            if label in TIMED:
                # A second run, compiled: the keyframes' extra registration per frame, in frames/s.
                started_run = time.perf_counter()
                jax.block_until_ready(run_bevo(model, data, warm_start=True))
                frames_per_s.setdefault(name, {})[label] = seq.num_frames / (time.perf_counter() - started_run)
            if label in (
                "BEVO + bands, uncalibrated IMU",
                "BEVO",
                "street",
                "street + robust bands",
                "street + robust bands, keyframes",
            ):
                trajectories[label] = np.asarray(out.poses, float)
            print(f"  {label}: {table[name][label]['final_pct']:.2f} % final", flush=True)
        assert street_out is not None
        street = street_model(seq.imu_dt, bands=False)
        inc = phase_correlate_peer(street, street_out, seq)
        put(name, "peer: cv2.phaseCorrelate on the street BEVs, turn from the gyro", segments(inc, None, seq))
        unit = essential_matrix_vo(seq)
        for oracle, label in (
            (True, "peer: essential-matrix VO, oracle scale"),
            (False, "peer: essential-matrix VO, first step's scale"),
        ):
            inc = scaled_steps(unit, seq, oracle)
            put(name, label, segments(inc, None, seq))
            if oracle:
                trajectories[label] = compose(np.asarray(seq.planar[0]), inc[1:])
        n = seq.num_frames
        for label, (bands, select) in LEARNED.items():
            trainer = Trainer(street_model(seq.imu_dt, bands=bands), select, args.lr)
            for test_half, train_half in zip(HALVES, HALVES[::-1]):
                (start, stop), (v_start, v_stop) = split_training(*half_frames(n, train_half))
                train = sq.window(seq, start, stop - start)
                held_out = sq.window(seq, v_start, v_stop - v_start)
                per_seed = []
                for seed in range(args.seeds):
                    fitted = fit_held_out(trainer, train, held_out, seed, args)
                    out = run_bevo(fitted.model, seq, warm_start=True)
                    per_seed.append(scores(out.increments, out.pitch_roll, seq, *half_frames(n, test_half)))
                    trained_on = f"trained on the {train_half}"
                    learned_params.setdefault(name, {}).setdefault(label, {}).setdefault(trained_on, []).append(
                        learned_parameters(fitted.model)
                    )
                    selection.setdefault(name, {}).setdefault(label, {}).setdefault(trained_on, []).append(
                        {"step": fitted.step, "validation_final_pct": fitted.validation}
                    )
                put(name, label, {test_half: summarise(per_seed)})
                print(
                    f"  {label}, tested on the {test_half}: {table[f'{name} {test_half}'][label]['final_pct']:.2f} % final",
                    flush=True,
                )
        trajectory_top_view(RESULTS / f"real_kitti_{name}.png", seq.planar, trajectories, legend_below=True)

    write_json_atomic(
        args.out,
        {
            "settings": {
                **{k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
                "calibration_drives": [
                    n for n in kitti_imu.RECORDING_DAYS[CALIBRATION_DAY] if n in KITTI_TRAIN and n not in RUNS
                ],
            },
            "runs": table,
            "imu_interpolated_frames": {name: frames.tolist() for name, frames in dropouts.items()},
            "training_tilt_rate_rms_deg_s": training_tilt_rate_rms(Path(root)),
            "gyro_alone_drift_deg": {
                name: {"frames": GYRO_WINDOW, "from_frame": gyro_alone_drift(seq)} for name, (_, seq) in runs.items()
            },
            "learned_parameters": learned_params,
            "checkpoint_selection": selection,
            "frames_per_s": frames_per_s,
            "seconds": time.time() - started,
            "device": jax.devices()[0].device_kind,
        },
    )
    print(f"wrote {args.out} in {time.time() - started:.0f} s")


if __name__ == "__main__":
    main()
