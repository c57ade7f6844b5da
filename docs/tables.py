"""The generated tables and values of the README and docs/, each a function of committed JSON.

:data:`TABLES` and :data:`VALUES` map a marker's name (see ``docs/build.py``) to a function that
reads the records under ``benchmarks/results/`` and ``experiments/results/`` and returns Markdown.
Learned figures over several training seeds are written as ``mean ± standard deviation`` over the
seeds (the number of seeds in the table's header); figures of one deterministic run are written
as they are.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from functools import cache
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

__all__ = ["TABLES", "VALUES"]


@cache
def record(name: str) -> dict:
    """The JSON record ``name`` (a path relative to the project root)."""
    return json.loads((ROOT / name).read_text())


def table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A Markdown table; the first column left-aligned, the others right-aligned."""
    lines = ["| " + " | ".join(header) + " |", "| --- |" + " ---: |" * (len(header) - 1)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def num(x: float | None, digits: int = 2) -> str:
    """``x`` with ``digits`` decimals; ``-`` for a missing value (no segment, no run)."""
    return "-" if x is None else f"{x:.{digits}f}"


def spread(values: Sequence[float | None], digits: int = 2) -> str:
    """``mean ± sd`` of the values over seeds (population standard deviation); the value alone
    where every seed gives the same; ``-`` if any is missing."""
    if not values or any(v is None for v in values):
        return "-"
    a = np.asarray(values, float)
    if np.all(a == a[0]):  # the same run on every seed (hand-set parameters on fixed drives)
        return f"{a[0]:.{digits}f}"
    return f"{a.mean():.{digits}f} ± {a.std():.{digits}f}"


def seeds_of(runs: dict) -> list[str]:
    """The seed keys of a ``{seed: run}`` dict, in numeric order."""
    return sorted(runs, key=int)


# ----------------------------------------------------------------------------- filtering


def filtering_demo() -> str:
    d = record("experiments/results/filtering_demo.json")
    seeds = seeds_of(d["seeds"])
    keys = [
        ("position_rmse_m", "position RMSE (m)"),
        ("position_max_m", "max position error (m)"),
        ("yaw_mean_deg", "mean yaw error (deg)"),
    ]
    rows = []
    for part, label in (("before", "hand-set (wrong Q, R)"), ("after", "learned")):
        rows.append([label, *(spread([d["seeds"][s][part][k] for s in seeds], 3) for k, _ in keys)])
    return table([f"validation drives ({len(seeds)} seeds)", *(h for _, h in keys)], rows)


def ukf_speed() -> str:
    d = record("benchmarks/results/ukf.json")
    runs = d["runs"]
    methods = [
        ("jbevo_single", "jbevo, one sequence"),
        ("jbevo_single_checked", "jbevo, one sequence, input checks on"),
        ("dynamax_single", "dynamax, one sequence"),
        ("filterpy_single", "filterpy, one sequence"),
        ("jbevo_vmap64", f"jbevo, vmap over {d['batch']}"),
        ("dynamax_vmap64", f"dynamax, vmap over {d['batch']}"),
        ("dynamax_vmap64_sincos", f"dynamax + jbevo's sincos, vmap over {d['batch']}"),
    ]
    rows = []
    for key, label in methods:
        ref = "jbevo_vmap64" if "vmap" in key else "jbevo_single"
        if key in runs[0]:
            values = [r[key] for r in runs]
            speed = f"{np.median(values):,.0f} ({min(values):,.0f} - {max(values):,.0f})"
            ratio = np.median([r[ref] / r[key] for r in runs])
        else:  # measured once (filterpy is slow), against the median of jbevo's runs
            speed, ratio = f"{d[key]:,.0f} (once)", d[ref] / d[key]
        rows.append([label, speed, f"{ratio:.2f}"])
    return table([f"method ({len(runs)} runs)", "steps/s, median (range)", "jbevo is x faster"], rows)


def ukf_forms() -> str:
    d = record("benchmarks/results/ukf.json")
    runs = d["runs"]
    rows = []
    for key, label, ref, ref_label in [
        ("jbevo_sqrt_single", "square-root UKF, one sequence", "jbevo_single", "covariance UKF"),
        (
            "jbevo_sqrt_single_lapack_qr",
            "square-root UKF with LAPACK's QR as tria, one sequence",
            "jbevo_sqrt_single",
            "square-root UKF",
        ),
        ("jbevo_sqrt_vmap64", f"square-root UKF, vmap over {d['batch']}", "jbevo_vmap64", "covariance UKF"),
        ("jbevo_smoother_single", "UKF + RTS smoother, one sequence", "dynamax_uks_single", "dynamax UKS"),
        ("jbevo_smoother_vmap64", f"UKF + RTS smoother, vmap over {d['batch']}", "dynamax_uks_vmap64", "dynamax UKS"),
        ("jbevo_sqrt_single", "square-root UKF, one sequence", "cuthbertlib_single", "cuthbertlib's"),
        ("jbevo_sqrt_vmap64", f"square-root UKF, vmap over {d['batch']}", "cuthbertlib_vmap64", "cuthbertlib's"),
        ("jbevo_smoother_single", "UKF + RTS smoother, one sequence", "cuthbertlib_uks_single", "cuthbertlib's"),
        ("jbevo_smoother_vmap64", f"UKF + RTS smoother, vmap over {d['batch']}", "cuthbertlib_uks_vmap64", "cuthbertlib's"),
    ]:
        values = [r[key] for r in runs]
        ratio = np.median([r[key] / r[ref] for r in runs])
        rows.append([label, f"{np.median(values):,.0f} ({min(values):,.0f} - {max(values):,.0f})", f"{ratio:.2f} x {ref_label}"])
    return table([f"method ({len(runs)} runs)", "steps/s, median (range)", "speed relative to"], rows)


def ukf_loop_variants(d: dict, before: str, after: str, speedup: str) -> list[list[str]]:
    """Rows of the filters' loops compiled two ways (``ukf.json``): per program, the median
    steps/s of the keys ``jbevo_<kind><before>`` and ``jbevo_<kind><after>``, and the median
    (range) over the runs of ``<speedup>_<kind>``."""
    runs = d["runs"]
    rows = []
    for kind, label in [
        ("single", "UKF, one sequence"),
        ("sqrt_single", "square-root UKF, one sequence"),
        ("smoother_single", "UKF + RTS smoother, one sequence"),
        ("vmap64", f"UKF, vmap over {d['batch']}"),
        ("grad_single", "gradient of the UKF's log-likelihood, one sequence"),
    ]:
        first, second = (np.median([r[f"jbevo_{kind}{suffix}"] for r in runs]) for suffix in (before, after))
        ratio = [r[f"{speedup}_{kind}"] for r in runs]
        rows.append([label, f"{first:,.0f}", f"{second:,.0f}", f"{np.median(ratio):.2f} ({min(ratio):.2f} - {max(ratio):.2f})"])
    return rows


def ukf_blocked() -> str:
    d = record("benchmarks/results/ukf.json")
    runs = d["runs"]
    rows = ukf_loop_variants(d, "", "_blocked", "blocked_speedup")
    for key, label in [
        ("speedup_single_vs_dynamax_blocked", "blocked UKF, one sequence, against dynamax's UKF"),
        ("smoother_speedup_single_vs_dynamax_blocked", "blocked UKF + RTS smoother, one sequence, against dynamax's UKS"),
    ]:
        ratio = [r[key] for r in runs]
        rows.append([label, "", "", f"{np.median(ratio):.2f} ({min(ratio):.2f} - {max(ratio):.2f})"])
    return table(
        [f"method ({len(runs)} runs)", "one lax.scan (steps/s)", 'block="auto" (steps/s)', "speed-up, median (range)"], rows
    )


def ukf_one_kernel() -> str:
    d = record("benchmarks/results/ukf.json")
    rows = ukf_loop_variants(d, "_plain_loop", "", "one_kernel_speedup")
    header = [f"method ({len(d['runs'])} runs)", "plain loop (steps/s)", "one kernel (steps/s)", "speed-up, median (range)"]
    return table(header, rows)


def ukf_compile() -> str:
    d = record("benchmarks/results/ukf.json")
    s = {
        k: d[f"compile_s_{k}"]
        for k in ("filter", "filter_blocked", "filter_plain_loop", "grad", "grad_blocked", "grad_plain_loop")
    }
    return (
        f"filter {s['filter']:.2f} s ({s['filter_blocked']:.2f} s in blocks, {s['filter_plain_loop']:.2f} s as a plain "
        f"loop); gradient {s['grad']:.2f} s ({s['grad_blocked']:.2f} s in blocks, {s['grad_plain_loop']:.2f} s as a plain "
        f"loop); one compile each. Max |difference| over the filter's and the smoother's outputs: blocks against one "
        f"scan {d['max_abs_diff_blocked_vs_plain']:.0e}, one kernel against the plain loop "
        f"{d['max_abs_diff_one_kernel_vs_plain_loop']:.0e}"
    )


def ukf_tria() -> str:
    """The square-root filter's unrolled ``tria`` against LAPACK's QR in its place, each loop as
    it compiles (``ukf.json``, medians of per-run ratios)."""
    runs = record("benchmarks/results/ukf.json")["runs"]
    plain = np.median([r["jbevo_sqrt_single_lapack_qr"] / r["jbevo_sqrt_single_plain_loop"] for r in runs])
    kernel = np.median([r["jbevo_sqrt_single"] / r["jbevo_sqrt_single_lapack_qr"] for r in runs])
    as_kernel = (
        f"the unrolled tria wins only as one kernel, and then by {kernel:.2f}x over LAPACK's QR in a plain loop"
        if kernel >= 1.02
        else f"as one kernel the unrolled tria runs at {kernel:.2f}x the speed of LAPACK's QR in a plain loop: no faster"
    )
    return (
        f"as plain loops, LAPACK's QR is {plain:.1f}x faster than the unrolled tria (whose many tiny kernels "
        f"each cost a call per step); {as_kernel} (one sequence, median of {len(runs)} runs)"
    )


def batch_last() -> str:
    """Batches held in the last axis (``vmap_last``) against ``jax.vmap`` and dynamax vmapped,
    from the same runs as the peer table (``ukf.json``)."""
    d = record("benchmarks/results/ukf.json")
    runs, b = d["runs"], d["batch"]
    rows = []
    for key, label, ratio, against in [
        ("jbevo_batch_last64", f"UKF, vmap_last over {b}", "batch_last_speedup_vs_vmap", "jax.vmap"),
        ("jbevo_batch_last64", f"UKF, vmap_last over {b}", "speedup_batch_last64_vs_dynamax", "dynamax's UKF, vmapped"),
        (
            "jbevo_smoother_batch_last64",
            f"UKF + RTS smoother, vmap_last over {b}",
            "smoother_speedup_batch_last64_vs_dynamax",
            "dynamax's UKS, vmapped",
        ),
        ("jbevo_grad_batch_last64", "gradient of the log-likelihoods, vmap_last", "grad_batch_last_speedup_vs_vmap", "jax.vmap"),
    ]:
        values, ratios = [r[key] for r in runs], [r[ratio] for r in runs]
        rows.append(
            [
                label,
                f"{np.median(values):,.0f} ({min(values):,.0f} - {max(values):,.0f})",
                f"{np.median(ratios):.2f} ({min(ratios):.2f} - {max(ratios):.2f}) x {against}",
            ]
        )
    rows.append(
        [
            f"max difference from jax.vmap: means and covariances {d['max_abs_diff_batch_last_vs_vmap']:.0e}, "
            f"gradient {d['max_rel_diff_grad_batch_last_vs_vmap']:.0e} (relative)",
            "",
            "",
        ]
    )
    return table([f"method ({len(runs)} runs, T = {d['T']:,})", "steps/s, median (range)", "speed-up, median (range)"], rows)


def parallel_in_time() -> str:
    d = record("benchmarks/results/parallel_in_time.json")
    rows = []
    for steps, r in d["by_steps"].items():
        s = r["seconds"]
        rows.append(
            [
                f"{int(steps):,}",
                f"{s['ukf_uks'] * 1e3:,.1f}",
                f"{s['ipls_sequential'] * 1e3:,.1f}",
                f"{s['ipls_parallel'] * 1e3:,.1f}",
                f"{r['parallel_over_sequential']['ipls_iteration']:.2f}",
                f"{r['parallel_over_sequential']['affine_filter_smoother']:.2f}",
                f"{r['parallel_over_sequential']['affine_filter_smoother_plain_loop']:.2f}",
                f"{r['max_abs_diff_parallel_vs_sequential']['smoothed_mean']:.0e}",
                str(r["iterations_to_converge"]),
                f"{r['span_ratio_sequential_over_parallel']:,.0f}",
            ]
        )
    return table(
        [
            "steps T",
            "UKF + URTS (ms)",
            "IPLS iteration, sequential (ms)",
            "IPLS iteration, parallel (ms)",
            "parallel / sequential",
            "affine filter + smoother alone, parallel / sequential",
            "the same, parallel / sequential as plain loops",
            "max |parallel - sequential|",
            "iterations to 1e-9",
            "span, sequential / parallel (T / 2 log2 T)",
        ],
        rows,
    )


def ukf_cuthbertlib_agreement() -> str:
    d = record("benchmarks/results/ukf.json")
    return f"{d['max_abs_diff_vs_cuthbertlib']:.1e} and {d['max_abs_diff_smoother_vs_cuthbertlib']:.1e}"


def parallel_in_time_summary() -> str:
    d = record("benchmarks/results/parallel_in_time.json")["by_steps"]
    steps = sorted(d, key=int)
    ratios = [d[t]["parallel_over_sequential"]["ipls_iteration"] for t in steps]
    # The crossover: the shortest length from which on every measured length favours parallel.
    cross = next((t for i, t in enumerate(steps) if all(r <= 1.0 for r in ratios[i:])), None)
    times = ", ".join(f"{r:.2f}" for r in ratios)
    lengths = ", ".join(f"{int(t):,}" for t in steps)
    where = (
        f"at least as fast as the sequential one from T = {int(cross):,} on"
        if cross
        else "slower than the sequential one at every length measured"
    )
    worst = max(d[t]["max_abs_diff_parallel_vs_sequential"]["smoothed_mean"] for t in steps)
    return (
        f"One parallel iteration takes {times} times the sequential one's time at T = {lengths}: on this CPU it is "
        f"{where}; the two agree to {worst:.0e} at every length."
    )


def localization_smoothing() -> str:
    d = record("experiments/results/localization_smoothing.json")
    rows = []
    for kind, entry in sorted(d["kinds"].items()):
        for condition, c in sorted(entry["conditions"].items()):
            f, sm = c["filtered"], c["smoothed"]
            rows.append(
                [
                    f"{kind}, {condition}",
                    num(f["mean_position_error_m"], 3),
                    num(sm["mean_position_error_m"], 3),
                    num(f["max_position_error_m"], 3),
                    num(sm["max_position_error_m"], 3),
                    num(f["mean_yaw_error_deg"], 3),
                    num(sm["mean_yaw_error_deg"], 3),
                ]
            )
    return table(
        [
            "test quarter, hand-set BEVO+",
            "mean error (m), filtered",
            "smoothed",
            "max error (m), filtered",
            "smoothed",
            "mean yaw error (deg), filtered",
            "smoothed",
        ],
        rows,
    )


def localization_smoothing_summary() -> str:
    d = record("experiments/results/localization_smoothing.json")
    ratios = [c["smoothed_over_filtered"] for k in d["kinds"].values() for c in k["conditions"].values()]
    pos = [1 - r["mean_position_error_m"] for r in ratios]
    yaw = [r["mean_yaw_error_deg"] - 1 for r in ratios]
    return (
        f"smoothing lowers the mean position error by {min(pos):.0%} to {max(pos):.0%} in every scene, and changes "
        f"the mean yaw error by {min(yaw):+.0%} to {max(yaw):+.0%}"
    )


def ukf_batch_last_vs_dynamax() -> str:
    d = record("benchmarks/results/ukf.json")
    ratios = [r["speedup_batch_last64_vs_dynamax"] for r in d["runs"]]
    return (
        f"{np.median(ratios):.2f}x ({min(ratios):.2f} - {max(ratios):.2f}) dynamax's vmapped UKF over {d['batch']} sequences "
        f"(jax.vmap: {d['speedup_vmap64_vs_dynamax']:.2f}x), median of {len(ratios)} runs"
    )


def ukf_agreement() -> str:
    d = record("benchmarks/results/ukf.json")
    return f"{d['max_abs_diff_vs_filterpy']:.1e} and {d['max_abs_diff_vs_dynamax']:.1e}"


def attitude_synthetic() -> str:
    d = record("benchmarks/results/attitude.json")
    rows = [
        ("accelerometer tilt only", d["rmse_deg_accel_only"], None),
        ("gyro integration only", d["rmse_deg_gyro_only"], None),
        ("DUKF (pitch, roll)", d["rmse_deg_dukf_handset"], d["rmse_deg_dukf_learned"]),
        ("DUKF + gyro bias", d["rmse_deg_dukf_gyro_bias_handset"], d["rmse_deg_dukf_gyro_bias_learned"]),
        ("motion-compensated + bias", d["rmse_deg_motion_compensated_handset"], d["rmse_deg_motion_compensated"]),
        ("speed-aided (BEVO's)", d["rmse_deg_speed_aided_handset"], d["rmse_deg_speed_aided"]),
        ("speed-aided, RTS-smoothed offline", d["rmse_deg_speed_aided_smoothed_handset"], d["rmse_deg_speed_aided_smoothed"]),
    ]
    return table(
        ["pitch and roll RMSE on 09 + 10 (deg)", "hand-set", "learned"],
        [[name, num(hand, 3), num(learned, 3)] for name, hand, learned in rows],
    )


ATTITUDE_REAL_ROWS = (
    ("accelerometer tilt only", "accel_only", None),
    ("gyro integration only", "gyro_only", None),
    ("DUKF (pitch, roll)", "dukf_handset", "dukf_learned"),
    ("DUKF + gyro bias", "dukf_gyro_bias_handset", "dukf_gyro_bias_learned"),
    ("motion-compensated + bias", "motion_compensated_handset", "motion_compensated_learned"),
    ("speed-aided (BEVO's)", "speed_aided_handset", "speed_aided_learned"),
    ("speed-aided, RTS-smoothed offline", "speed_aided_smoothed_handset", "speed_aided_smoothed_learned"),
)
PEER_NAMES = {"madgwick": "Madgwick", "mahony": "Mahony", "ekf": "EKF", "complementary": "complementary"}


def attitude_real() -> str:
    d = record("benchmarks/results/attitude_real.json")
    rmse, centred, raw = d["rmse_deg"], d["rmse_deg_offset_removed"], d["rmse_deg_uncalibrated"]
    rows = []
    for name, hand, learned in ATTITUDE_REAL_ROWS:
        rows.append(
            [
                name,
                num(raw.get(hand), 3),
                num(rmse.get(hand), 3),
                num(rmse.get(learned) if learned else None, 3),
                num(centred.get(learned or hand), 3),
            ]
        )
    for key, name in PEER_NAMES.items():
        peer = d["peers"][key]
        rows.append(
            [
                f"`ahrs` {name} (gain {peer['gain']:g})",
                "-",
                num(peer["rmse_deg"], 3),
                "-",
                num(peer["rmse_deg_offset_removed"], 3),
            ]
        )
    return table(
        [
            "pitch and roll RMSE on real 09 + 10 (deg)",
            "uncalibrated, hand-set",
            "hand-set",
            "learned",
            "learned, offsets removed",
        ],
        rows,
    )


def attitude_real_headline() -> str:
    d = record("benchmarks/results/attitude_real.json")
    rmse, raw = d["rmse_deg"], d["rmse_deg_uncalibrated"]
    best = min(d["peers"], key=lambda k: d["peers"][k]["rmse_deg"])
    rows = [
        ["gyro integration only", num(raw["gyro_only"], 3), num(rmse["gyro_only"], 3)],
        ["DUKF (pitch, roll), learned", "-", num(rmse["dukf_learned"], 3)],
        ["speed-aided (BEVO's), hand-set", num(raw["speed_aided_handset"], 3), num(rmse["speed_aided_handset"], 3)],
        ["speed-aided (BEVO's), learned", "-", num(rmse["speed_aided_learned"], 3)],
        [f"best `ahrs` peer ({PEER_NAMES[best]}, gain tuned)", "-", num(d["peers"][best]["rmse_deg"], 3)],
    ]
    return table(["pitch and roll RMSE, real KITTI IMU, 09 + 10 (deg)", "uncalibrated", "calibrated"], rows)


def attitude_real_calibration() -> str:
    d = record("benchmarks/results/attitude_real.json")["calibration"]
    rows = []
    for day, c in d["per_day"].items():
        sd = c["std"]
        rot = ", ".join(f"{v:.2f} ± {e:.2f}" for v, e in zip(c["rotation_body_imu_deg"], sd["rotation_body_imu_deg"]))
        rows.append(
            [
                f"{day} ({' '.join(c['fitted_on'])})",
                rot,
                f"{1000 * c['time_offset_s']:.1f} ± {1000 * sd['time_offset_s']:.1f}",
                f"{c['gyro_scale']:.4f} ± {sd['gyro_scale']:.4f}",
                ", ".join(f"{v:.3f}" for v in c["accel_bias_m_s2"][:2]),
                ", ".join(f"{v:.2f}" for v in c["estimate_minus_published_deg"]),
            ]
        )
    return table(
        [
            "recording day (fitted on)",
            "mounting x, y, z (deg)",
            "time offset (ms)",
            "gyro scale",
            "accel bias x, y (m/s^2)",
            "minus published 2011_09_26 chain (deg)",
        ],
        rows,
    )


def attitude_world_tilt() -> str:
    d = record("benchmarks/results/attitude_real.json")["calibration"]
    return ", ".join(f"{n}: {t:.1f}" for n, t in d["world_tilt_deg"].items())


def attitude_euroc() -> str:
    d = record("benchmarks/results/attitude_real.json")["euroc"]
    rmse = d["rmse_deg"]
    rows = [
        [name, num(rmse[hand], 2), num(rmse.get(learned) if learned else None, 2)]
        for name, hand, learned in ATTITUDE_REAL_ROWS
        if hand in rmse
    ]
    rows += [
        [f"`ahrs` {n} (gain {d['peers'][k]['gain']:g})", num(d["peers"][k]["rmse_deg"], 2), "-"] for k, n in PEER_NAMES.items()
    ]
    return table(["pitch and roll RMSE on EuRoC V1_02, quarter 4 (deg)", "hand-set", "learned"], rows)


def imu_noise_real() -> str:
    n = record("benchmarks/results/attitude_real.json")["imu_noise"]
    adis = n["adis16448"]
    fmt = lambda values: ", ".join(f"{v:.1e}" for v in values)
    rows = [
        [
            "gyro white noise (rad/s/sqrt(Hz))",
            fmt(n["gyro_noise_density_rad_s_sqrt_hz"]),
            f"{adis['gyro_noise_density_rad_s_sqrt_hz']:.1e}",
        ],
        [
            "gyro bias random walk (rad/s^2/sqrt(Hz))",
            "< " + fmt(n["gyro_random_walk_bound_rad_s2_sqrt_hz"]),
            f"{adis['gyro_random_walk_rad_s2_sqrt_hz']:.1e}",
        ],
        ["gyro bias, spread between drives (rad/s)", fmt(n["gyro_bias_spread_rad_s"]), "-"],
        [
            "accel white noise (m/s^2/sqrt(Hz))",
            fmt(n["accel_noise_density_m_s2_sqrt_hz"]),
            f"{adis['accel_noise_density_m_s2_sqrt_hz']:.1e}",
        ],
        ["accel bias, spread between drives (m/s^2)", fmt(n["accel_bias_spread_m_s2"][:2]), "-"],
    ]
    return table(["", "KITTI OXTS RT3003 (x, y, z)", "ADIS16448 (EuRoC)"], rows)


# ----------------------------------------------------------------------------- registration


def registration_sets() -> str:
    d = record("benchmarks/results/registration.json")
    rows = []
    for name, s in d["sets"].items():
        seeds = seeds_of(s["seeds"])
        pairs = d["config"]["pairs_per_set_and_seed"] * len(seeds)
        cells = [name]
        for kind, unit in (("T", "px"), ("R", "deg"), ("N", "deg")):
            med = np.median([s["seeds"][k][f"jbevo_{kind}_median_{unit}"] for k in seeds])
            p95 = np.median([s["seeds"][k][f"jbevo_{kind}_p95_{unit}"] for k in seeds])
            gross = sum(s["seeds"][k][f"jbevo_{kind}_gross"] for k in seeds)
            cells.append(f"{med:.3f} / {p95:.3f} ({gross}/{pairs})")
        cells.append(f"{np.median([s['seeds'][k]['jbevo_N_confidence_median'] for k in seeds]):.2f}")
        rows.append(cells)
    return table(["set", "T: px (gross)", "R: deg (gross)", "N: deg (gross)", "N: median confidence"], rows)


def registration_peers() -> str:
    s = record("benchmarks/results/registration.json")["sets"]["tuning"]["seeds"]["0"]
    rows = []
    for method in ("jbevo", "imreg_dft", "cv2", "skimage"):
        cells = [method]
        for kind, unit in (("T", "px"), ("R", "deg"), ("N", "deg")):
            key = f"{method}_{kind}"
            if f"{key}_median_{unit}" in s:
                cells.append(
                    f"{s[f'{key}_median_{unit}']:.3f} / {s[f'{key}_p95_{unit}']:.3f}, {s[f'{key}_gross']} gross, {s[f'{key}_ms']:.2f} ms"
                )
            else:
                cells.append("-")
        rows.append(cells)
    return table(["method", "T: median / p95 px", "R: median / p95 deg", "N: median / p95 deg"], rows)


# ----------------------------------------------------------------------------- BEV, simulator, BEVO speed


def bev_speed() -> str:
    d = record("benchmarks/results/bev.json")
    rows = [
        ["jbevo (JAX, batched)", f"{d['jbevo_bev_per_s']:,.0f}", "1.00"],
        ["OpenCV warpPerspective", f"{d['opencv_bev_per_s']:,.0f}", f"{d['jbevo_bev_per_s'] / d['opencv_bev_per_s']:.2f}"],
        [
            "dm-pix flat_nd_linear_interpolate",
            f"{d['dm_pix_bev_per_s']:,.0f}",
            f"{d['jbevo_bev_per_s'] / d['dm_pix_bev_per_s']:.2f}",
        ],
    ]
    return table([f"BEV {d['config']['bev']} from {d['config']['image']}", "BEVs/s", "jbevo / this"], rows)


def bevo_speed() -> str:
    d = record("benchmarks/results/bevo.json")
    nb = d["without_bands"]
    rows = [
        ["inference (frames/s)", num(d["inference_frames_per_s"], 0), num(nb["inference_frames_per_s"], 0)],
        [
            f"training, {d['window_frames']}-frame windows (frames/s)",
            num(d["train_frames_per_s"], 0),
            num(nb["train_frames_per_s"], 0),
        ],
        [
            f"peak memory of a {d['window_frames']}-frame gradient (GB)",
            num(d["peak_memory_gb_window64"], 3),
            num(nb["peak_memory_gb_window64"], 3),
        ],
        ["learnable parameters", str(d["learnable_parameters"]), str(nb["learnable_parameters"])],
    ]
    return table(["BEVO, KITTI-size camera, 2-core CPU", "with bands", "without bands"], rows)


def scaling_throughput() -> str:
    d = record("benchmarks/results/scaling.json")["throughput"]
    rows = [
        [
            name,
            num(r["train_frames_per_s"], 0),
            f"{r['train_speedup']:.2f}",
            num(r["inference_frames_per_s"], 0),
            f"{r['inference_speedup']:.2f}",
            num(r["train_step_memory_per_device_mb"], 1),
            " / ".join(f"{m / 1024:.2f}" for m in r["peak_rss_mb_per_process"]),
            f"{r['final_loss_relative_difference']:.0e}",
        ]
        for name, r in d["configs"].items()
    ]
    header = [
        "2-core CPU",
        "training (frames/s)",
        "x 1 device",
        "inference (frames/s)",
        "x 1 device",
        "step memory per device (MB)",
        "peak RSS per process (GB)",
        "loss vs 1 device (rel.)",
    ]
    return table(header, rows)


def scaling_memory() -> str:
    d = record("benchmarks/results/scaling.json")["memory"]
    labels = {"copies": "every window copied", "indices": "windows as start indices (Windows)"}
    rows = [
        [
            labels[key],
            str(r["window_count"]),
            num(r["drive_images_gb"], 2),
            num(r["window_copies_gb"], 2),
            num(r["peak_rss_gb"], 2),
        ]
        for key, r in d["rows"].items()
    ]
    rows.append(["peak RSS, copies / indices", "", "", "", f"{d['peak_rss_ratio']:.2f}x"])
    return table(
        ["KITTI-style training set + one step", "windows", "drive images (GB)", "window copies (GB)", "peak RSS (GB)"], rows
    )


def simulator_speed() -> str:
    d = record("benchmarks/results/simulator.json")
    rows = [
        ["KITTI-size frame with exposure, sensor noise and 8-bit output (frames/s)", num(d["frames_per_s_kitti_size"], 0)],
        ["KITTI-size frame, rendering only (frames/s)", num(d["render_only_frames_per_s_kitti_size"], 0)],
        ["building a town (s)", num(d["world_build_s"], 2)],
        ["a 200-frame drive with the small camera (s)", num(d["procedural_sequence_200_frames_small_camera_s"], 2)],
        [
            f"street world: KITTI-size frame with its {d['street_structures_per_frame']} nearest structures, exposure gain "
            "and vignetting (frames/s)",
            num(d["street_frames_per_s_kitti_size"], 1),
        ],
        ["street world: flat world's frames/s over the street world's (same process)", num(d["street_slowdown_kitti_size"], 2)],
        [
            "street world: a 200-frame drive with the small camera (s)",
            num(d["street_procedural_sequence_200_frames_small_camera_s"], 2),
        ],
    ]
    return table(["simulator", "measured"], rows)


# ----------------------------------------------------------------------------- BEVO accuracy

SCORE_KEYS = [
    ("t_err_pct", "t_err (%)"),
    ("r_err_deg_per_100m", "r_err (deg/100 m)"),
    ("ate_m", "ATE (m)"),
    ("motion_rmse_m", "motion RMSE (m)"),
]


def builtin_training() -> str:
    d = record("experiments/results/builtin_training.json")
    seeds = seeds_of(d["seeds"])
    rows = []
    for part, part_label in (("validation", "validation drive"), ("test", "test drives")):
        for name, label in (("hand_set", "hand-set"), ("learned", "learned (best.ckpt)")):
            values = [d["seeds"][s][part][name] for s in seeds]
            digits = {"t_err_pct": 2, "r_err_deg_per_100m": 2, "ate_m": 2, "motion_rmse_m": 3}
            rows.append([f"{part_label}, {label}", *(spread([v[k] for v in values], digits[k]) for k, _ in SCORE_KEYS)])
    return table([f"python -m jbevo.train ({len(seeds)} seeds)", *(h for _, h in SCORE_KEYS)], rows)


def builtin_best_epochs() -> str:
    d = record("experiments/results/builtin_training.json")
    return ", ".join(str(d["seeds"][s]["best_epoch"]) for s in seeds_of(d["seeds"]))


def builtin_wins() -> str:
    d = record("experiments/results/builtin_training.json")
    seeds = seeds_of(d["seeds"])

    def wins(part: str) -> int:
        runs = [d["seeds"][s][part] for s in seeds]
        return sum(r["learned"]["t_err_pct"] < r["hand_set"]["t_err_pct"] for r in runs)

    return (
        f"{wins('validation')} of {len(seeds)} seeds on the validation drive, {wins('test')} of {len(seeds)} on the test drives"
    )


def bands() -> str:
    d = record("experiments/results/bands.json")
    rows = []
    for name, r in d["results"].items():
        rows.append(
            [
                name,
                num(r["t_err_pct"]),
                num(r["r_err_deg_per_100m"]),
                num(r["ate_m"]),
                num(r["motion_rmse_m"], 3),
                num(r["pitch_rms_deg"], 3),
                num(r["roll_rms_deg"], 3),
            ]
        )
    return table(
        [
            f"KITTI {d['sequence']}, {d['frames']} frames",
            "t_err (%)",
            "r_err (deg/100 m)",
            "ATE (m)",
            "motion RMSE (m)",
            "pitch RMS (deg)",
            "roll RMS (deg)",
        ],
        rows,
    )


KITTI_SIMULATED_IMU = "experiments/results/kitti_odometry.json"
KITTI_REAL_IMU = "experiments/results/kitti_odometry_real_imu.json"
KITTI_STREET = "experiments/results/kitti_odometry_street.json"


def learned_label(d: dict) -> str:
    """What a KITTI-style record's learned rows are (records before ``--model`` trained BEVO)."""
    return d.get("learned_label", "BEVO learned")


def kitti_odometry(name: str = KITTI_SIMULATED_IMU) -> str:
    d = record(name)
    tests = d["test"]
    seeds = seeds_of(d["learned"])
    header = ["method", *(f"{t} t_err (%)" for t in tests), "pooled t_err (%)", "pooled r_err (deg/100 m)"]
    rows = [
        [
            f"{learned_label(d)} ({len(seeds)} seeds)",
            *(spread([d["learned"][s][t]["t_err_pct"] for s in seeds]) for t in tests),
            spread([d["learned"][s]["pooled"]["t_err_pct"] for s in seeds]),
            spread([d["learned"][s]["pooled"]["r_err_deg_per_100m"] for s in seeds]),
        ]
    ][: 1 if seeds else 0]
    for name, r in d["hand_set"].items():
        rows.append(
            [
                name,
                *(num(r[t]["t_err_pct"]) for t in tests),
                num(r["pooled"]["t_err_pct"]),
                num(r["pooled"]["r_err_deg_per_100m"]),
            ]
        )
    return table(header, rows)


def kitti_validation(name: str = KITTI_SIMULATED_IMU) -> str:
    d = record(name)
    rows = []
    for s in seeds_of(d["training"]):
        r = d["training"][s]
        if r.get("failed"):
            rows.append([f"seed {s}: training failed (non-finite values)", "-", "-", "-", "-"])
            continue
        for name, label in (("validation_hand_set", "hand-set"), ("validation_learned", "learned")):
            v = r[name]
            rows.append(
                [
                    f"seed {s}, {label}",
                    num(v["t_err_pct"]),
                    num(v["r_err_deg_per_100m"]),
                    num(v["ate_m"]),
                    num(v["motion_rmse_m"], 3),
                ]
            )
        rows[-1][0] += f" (epoch {r['best_epoch']})"
    return table(["08 (validation)", "t_err (%)", "r_err (deg/100 m)", "ATE (m)", "motion RMSE (m)"], rows)


def kitti_worlds() -> str:
    """The flat and the street world's pooled 09 + 10 errors side by side."""
    flat, street = record(KITTI_SIMULATED_IMU), record(KITTI_STREET)

    def learned(d: dict, label: str, key: str) -> str:
        if learned_label(d) != label or not d["learned"]:
            return "-"
        return spread([d["learned"][s]["pooled"][key] for s in seeds_of(d["learned"])])

    def hand(d: dict, label: str, key: str) -> str:
        return num(d["hand_set"][label]["pooled"][key]) if label in d["hand_set"] else "-"

    rows = []
    for label in dict.fromkeys(learned_label(d) for d in (flat, street)):
        counts = [len(seeds_of(d["learned"])) if learned_label(d) == label else 0 for d in (flat, street)]
        if counts[0] == counts[1]:
            seeds = f"{counts[0]} seeds"
        elif 0 in counts:
            seeds = f"{max(counts)} seeds, {'flat' if counts[0] else 'street'} world"
        else:
            seeds = f"{counts[0]} seeds; {counts[1]} in the street world"
        rows.append(
            [f"{label} ({seeds})"] + [learned(d, label, k) for k in ("t_err_pct", "r_err_deg_per_100m") for d in (flat, street)]
        )
    for label in street["hand_set"]:
        rows.append([label] + [hand(d, label, k) for k in ("t_err_pct", "r_err_deg_per_100m") for d in (flat, street)])
    header = ["09 + 10 pooled", "t_err flat (%)", "t_err street (%)", "r_err flat (deg/100 m)", "r_err street (deg/100 m)"]
    return table(header, rows)


def kitti_training_sequences(name: str = KITTI_STREET) -> str:
    """t_err on the frames each training and validation sequence was trained or validated on."""
    d = record(name)["training_sequences"]
    names = sorted(next(iter(d.values())))
    rows = [[label] + [num(d[label][n]["t_err_pct"]) for n in names] for label in d]
    return table(["t_err (%) over the training and validation frames", *names], rows)


def kitti_wins(name: str = KITTI_SIMULATED_IMU) -> str:
    d = record(name)
    seeds = seeds_of(d["learned"])
    if not seeds:
        return "no seed trained"
    baseline = "street preset (hand-set)" if d.get("model") == "street" else "BEVO hand-set"
    hand = d["hand_set"][baseline]["pooled"]["t_err_pct"]
    test = sum(d["learned"][s]["pooled"]["t_err_pct"] < hand for s in seeds)
    runs = [d["training"][s] for s in seeds]
    val = sum(r["validation_learned"]["t_err_pct"] < r["validation_hand_set"]["t_err_pct"] for r in runs)
    return f"{val} of {len(seeds)} seeds on 08 (validation), {test} of {len(seeds)} on 09 + 10 (pooled)"


# ----------------------------------------------------------------------------- localization


LOCALIZATION = "experiments/results/localization.json"
LOCALIZATION_STREET = "experiments/results/localization_street.json"
LOCALIZATION_STREET_PRESET = "experiments/results/localization_street_preset.json"


def _localization(kind: str, name: str = LOCALIZATION) -> str:
    d = record(name)["results"][kind]
    conditions = list(d["hand_set"])
    seeds = seeds_of(d["learned"])
    header = ["mean position error (m)", *conditions]
    rows = [
        [
            f"BEVO+ learned ({len(seeds)} seed{'s' if len(seeds) > 1 else ''})",
            *(spread([d["learned"][s][c]["mean_position_error_m"] for s in seeds], 3) for c in conditions),
        ],
        ["BEVO+ hand-set", *(num(d["hand_set"][c]["mean_position_error_m"], 3) for c in conditions)],
        ["BEVO odometry alone", *(num(d["odometry_alone"][c]["mean_position_error_m"], 3) for c in conditions)],
        ["map matching alone", *(num(d["map_matching_alone"][c]["mean_position_error_m"], 3) for c in conditions)],
    ]
    return table(header, rows)


def localization_carla() -> str:
    return _localization("carla")


def localization_aeroground() -> str:
    return _localization("aeroground")


def localization_wins(name: str = LOCALIZATION) -> str:
    results = record(name)["results"]
    parts = []
    for kind, d in results.items():
        seeds, conditions = seeds_of(d["learned"]), list(d["hand_set"])
        key = "mean_position_error_m"
        wins = sum(d["learned"][s][c][key] < d["hand_set"][c][key] for s in seeds for c in conditions)
        parts.append(f"{kind} {wins} of {len(seeds) * len(conditions)}")
    return ", ".join(parts)


def localization_validation() -> str:
    results = record("experiments/results/localization.json")["results"]
    rows = []
    for kind, d in results.items():
        seeds = seeds_of(d["training"])
        runs = [d["training"][s] for s in seeds]
        rows.append(
            [
                kind,
                spread([r["validation_hand_set"]["mean_position_error_m"] for r in runs], 3),
                spread([r["validation_learned"]["mean_position_error_m"] for r in runs], 3),
                ", ".join(str(r["best_epoch"]) for r in runs),
            ]
        )
    return table(["validation quarter (mean position error, m)", "hand-set", "learned", "best epoch per seed"], rows)


# ----------------------------------------------------------------------------- evaluation


def reference_metrics() -> str:
    d = record("experiments/results/reference_metrics.json")
    rows = []
    for name, r in d.items():
        pub, got = r["published"], r["measured"]
        rows.append(
            [
                name,
                r["alignment"],
                f"{got['t_err_pct']:.4f} ({pub['t_err_pct']})",
                f"{got['r_err_deg_per_100m']:.4f} ({pub['r_err_deg_per_100m']})",
                f"{got['ate_m']:.4f}" + (f" ({pub['ate_m']})" if "ate_m" in pub else ""),
            ]
        )
    return table(["trajectory", "alignment", "t_err % (published)", "r_err deg/100 m (published)", "ATE m (published)"], rows)


# ----------------------------------------------------------------------------- real frames

REAL_KITTI = "benchmarks/results/real_kitti.json"
REAL_KITTI_HEADLINE = [
    "BEVO, uncalibrated IMU",
    "BEVO + bands",
    "street",
    "street + robust bands",
    "street + robust bands, learned",
    "peer: cv2.phaseCorrelate on the street BEVs, turn from the gyro",
    "peer: essential-matrix VO, oracle scale",
]


def _metric(metrics: dict | None, key: str, digits: int) -> str:
    """A metric of one run (``num``) or over seeds (``spread``); ``-`` where absent."""
    if metrics is None or key not in metrics:
        return "-"
    if f"{key}_seeds" in metrics:
        return spread(metrics[f"{key}_seeds"], digits)
    return num(metrics[key], digits)


#: A real run whose pitch or roll leaves the truth by more than this (deg) has diverged: where its
#: trajectory ends is then a matter of round-off, and the headline marks it.
DIVERGED_DEG = 5.0


def real_kitti_headline() -> str:
    runs = record(REAL_KITTI)["runs"]
    keys = ["06", "06 second half", "07", "07 second half"]

    def cell(metrics: dict | None) -> str:
        text = _metric(metrics, "final_pct", 1)
        diverged = metrics is not None and metrics.get("pitch_roll_max_deg", 0.0) > DIVERGED_DEG
        return f"{text} (diverged)" if diverged else text

    rows = [[name] + [cell(runs[k].get(name)) for k in keys] for name in REAL_KITTI_HEADLINE]
    seeds = record(REAL_KITTI)["settings"]["seeds"]
    header = [
        f"final position error, % of distance (learned: {seeds} seeds)",
        "06 (59 m)",
        "06, 2nd half",
        "07 (91 m)",
        "07, 2nd half",
    ]
    return table(header, rows)


def real_kitti(run: str) -> str:
    d = record(REAL_KITTI)["runs"][run]
    columns = [
        ("motion_cm", "motion RMSE (cm)", 1),
        ("distance_ratio", "distance ratio", 3),
        ("yaw_deg", "yaw RMSE (deg/frame)", 3),
        ("final_pct", "final error (%)", 2),
        ("pitch_roll_max_deg", "pitch/roll max error (deg)", 2),
    ]
    rows = [[name] + [_metric(m, key, digits) for key, _, digits in columns] for name, m in d.items()]
    first = next(iter(d.values()))
    return table([f"{run}: {first['frames']} frames, {first['distance_m']:.1f} m"] + [c[1] for c in columns], rows)


def _frame_spans(frames: list[int]) -> str:
    """``[1, 2, 3, 7]`` as ``1-3, 7``; ``none`` if empty."""
    spans: list[list[int]] = []
    for f in frames:
        if spans and f == spans[-1][1] + 1:
            spans[-1][1] = f
        else:
            spans.append([f, f])
    return ", ".join(f"{a}-{b}" if b > a else f"{a}" for a, b in spans) or "none"


def real_kitti_imu_dropouts() -> str:
    """The runs' IMU dropouts, the gyro's drift over them, and the preset's pitch/roll error with
    the published IMU and with the dropout's blocks marked missing (with and without widening)."""
    d = record(REAL_KITTI)
    model = "street + robust bands"
    marked = f"{model}, IMU dropouts missing"
    held = f"{marked}, attitude not widened"
    rows = []
    for run, frames in d["imu_interpolated_frames"].items():
        drift = d["gyro_alone_drift_deg"][run]["from_frame"]
        after = frames[-1] + 1 if frames else 1  # the first start whose IMU blocks were all recorded
        worst = d["runs"][run][model]
        rows.append(
            [
                run,
                _frame_spans(frames),
                f"{drift[0]:.2f}",
                f"{max(drift[after:]):.2f}",
                str(worst["pitch_roll_worst_frame"]),
                " / ".join(f"{d['runs'][run][v]['pitch_roll_max_deg']:.2f}" for v in (model, held, marked)),
                " / ".join(f"{d['runs'][run][v]['pitch_roll_rmse_deg']:.2f}" for v in (model, held, marked)),
            ]
        )
    window = next(iter(d["gyro_alone_drift_deg"].values()))["frames"]
    header = [
        "run",
        "frames the published IMU interpolates",
        f"gyro alone from the truth at frame 0: worst over {window} frames (deg)",
        "the same from any later start past the dropout, largest (deg)",
        f"{model}: worst pitch/roll frame",
        "worst pitch/roll error (deg): published IMU / dropouts missing, held / widened",
        "pitch/roll RMSE (deg), the same three",
    ]
    return table(header, rows)


IMU_DROPOUTS = "benchmarks/results/imu_dropouts.json"


def imu_dropouts_truth_bend() -> str:
    """The truth's largest bend inside the dropouts, per drive, and its median elsewhere."""
    drives = record(IMU_DROPOUTS)["drives"]
    names = list(drives)
    listed = lambda xs: ", ".join(xs[:-1]) + " and " + xs[-1] if len(xs) > 1 else xs[0]
    inside = listed([f"{drives[n]['truth_bend_deg']['dropouts_max']:.2f}" for n in names])
    elsewhere = listed([f"{drives[n]['truth_bend_deg']['elsewhere_median']:.2f}" for n in names])
    return f"{inside} deg per frame on {listed(names)} (median elsewhere {elsewhere})"


def imu_dropouts() -> str:
    """The street preset's attitude filter on every KITTI drive whose published IMU has dropouts:
    the published rows against the dropouts marked missing (held, widened)."""
    d = record(IMU_DROPOUTS)
    after = d["settings"]["after_frames"]
    variants = ("published", "held", "widened")
    rows = []
    for name, drive in d["drives"].items():
        rows.append(
            [
                name,
                str(len(drive["gaps"])),
                " / ".join(f"{drive[v]['rmse_deg']:.3f}" for v in variants),
                " / ".join(f"{drive[v]['near_gaps_rmse_deg']:.2f}" for v in variants),
                " / ".join(f"{drive[v]['near_gaps_max_deg']:.2f}" for v in variants),
            ]
        )
    rows.append(["pooled", "", " / ".join(f"{d['pooled']['rmse_deg'][v]:.3f}" for v in variants), "", ""])
    header = [
        "drive",
        "dropouts",
        "pitch/roll RMSE (deg): published / missing, held / widened",
        f"the same from each dropout to {after} frames past it",
        "largest error there (deg), the same three",
    ]
    return table(header, rows)


FORWARD_FUSION = "benchmarks/results/forward_fusion.json"
FORWARD_COLUMNS = [
    ("distance_ratio", "distance ratio", 3),
    ("final_pct", "final error (%)", 2),
    ("motion_cm", "motion RMSE (cm)", 1),
    ("along_cm", "along the heading (cm)", 1),
    ("across_cm", "across (cm)", 1),
    ("pitch_roll_max_deg", "pitch/roll max error (deg)", 2),
]


#: The forward-fusion record's rows of the constant-speed prior start with this, the walk follows.
SPEED_PRIOR = "constant-speed prior without the accelerometer, speed walk "


def _forward_rows(kind: str, first: str) -> str:
    """The forward-fusion record's ``kind`` table (``runs`` or ``street_world``), the rows of the
    accelerometer noise's sweep and of the constant-speed prior left out (tables of their own)."""
    rows = [
        [f"{segment}: {name}"] + [num(m[key], digits) for key, _, digits in FORWARD_COLUMNS]
        for segment, values in record(FORWARD_FUSION)[kind].items()
        for name, m in values.items()
        if "(sweep)" not in name and not name.startswith(SPEED_PRIOR)
    ]
    return table([first] + [c[1] for c in FORWARD_COLUMNS], rows)


def forward_fusion() -> str:
    return _forward_rows("runs", "run: model")


def forward_fusion_sweep() -> str:
    d = record(FORWARD_FUSION)
    rows = []
    for accel_std in d["settings"]["sweep"]:
        name = f"forward fusion, accel_std {accel_std} (sweep)"
        cells = []
        for run in ("06", "07"):
            m = d["runs"][run][name]
            cells += [num(m["final_pct"], 2), num(m["motion_cm"], 1)]
        rows.append([f"{accel_std:g}"] + cells)
    header = ["accel_std (m/s^2 per sample)", "06: final (%)", "06: motion (cm)", "07: final (%)", "07: motion (cm)"]
    return table(header, rows)


def forward_fusion_prior() -> str:
    """The preset, forward fusion, and DPC's increments under a constant-speed prior without the
    accelerometer, per speed walk: per-frame motion and final error on the runs and second halves."""
    d = record(FORWARD_FUSION)
    labels = {
        "street + robust bands": "street + robust bands",
        "street + robust bands, forward fusion": "forward fusion (accelerometer)",
    } | {f"{SPEED_PRIOR}{w}": f"constant-speed prior, no accelerometer, walk {w:g}" for w in d["settings"]["speed_walks"]}
    keys = ("06", "06 second half", "07", "07 second half")
    rows = [
        [shown] + [f"{d['runs'][k][name]['motion_cm']:.1f} / {d['runs'][k][name]['final_pct']:.2f}" for k in keys]
        for name, shown in labels.items()
    ]
    header = ["model (walk: m/s^2 per sample)"] + [f"{k}: motion (cm) / final (%)" for k in keys]
    return table(header, rows)


def forward_fusion_street_world() -> str:
    return _forward_rows("street_world", "street world's copy: model")


def forward_fusion_long() -> str:
    """The street world's KITTI 09 and 10, whole: the devkit's errors per drive and pooled, and
    the per-frame metrics per drive."""
    return _forward_devkit("kitti_street")


def forward_fusion_held_out() -> str:
    """The same on the street world's KITTI 02 and 05 (first frames)."""
    return _forward_devkit("held_out")


def _forward_devkit(section: str) -> str:
    """The forward-fusion record's ``section`` of devkit-scored drives: the devkit's errors per
    drive and pooled, and the per-frame metrics per drive."""
    d = record(FORWARD_FUSION)[section]
    drives = [name for name in d if name != "pooled"]
    rows = []
    for model in d["pooled"]:
        pooled = d["pooled"][model]
        cells = [num(d[name][model]["t_err_pct"], 2) for name in drives]
        cells += [num(pooled["t_err_pct"], 2), num(pooled["r_err_deg_per_100m"], 2)]
        for name in drives:
            m = d[name][model]
            cells.append(f"{num(m['distance_ratio'], 3)} / {num(m['motion_cm'], 1)} / {num(m['along_cm'], 1)}")
        rows.append([model] + cells)
    header = ["model"] + [f"{name} t_err (%)" for name in drives] + ["pooled t_err (%)", "pooled r_err (deg/100 m)"]
    header += [f"{name}: distance ratio / motion RMSE / along the heading (cm)" for name in drives]
    return table(header, rows)


def forward_fusion_bias_sweep() -> str:
    """The bias walk sweep on the street world's KITTI 00 and 08 (first frames), laid out as the
    long drives' table."""
    return _forward_devkit("bias_walk_sweep")


STREET_DRIVES = "benchmarks/results/street_drives.json"


def street_drives() -> str:
    """The street preset on the street world's KITTI 09 and 10 with one failure mode removed at a
    time: the devkit's errors, the whole-drive distance ratio and the spread of the 100 m pieces'."""
    rec = record(STREET_DRIVES)
    d, piece = rec["drives"], f"{rec['settings']['piece_m']:.0f} m"
    drives = [name for name in d if name != "pooled"]
    rows = []
    for world, pooled in d["pooled"].items():
        cells = [num(d[name][world]["t_err_pct"], 2) for name in drives]
        cells += [num(pooled["t_err_pct"], 2), num(pooled["r_err_deg_per_100m"], 2)]
        cells += [f"{num(d[name][world]['distance_ratio'], 3)} / {num(d[name][world]['piece_scale_std'], 3)}" for name in drives]
        rows.append([world] + cells)
    header = ["world"] + [f"{name} t_err (%)" for name in drives] + ["pooled t_err (%)", "pooled r_err (deg/100 m)"]
    header += [f"{name}: distance ratio / {piece} pieces' spread" for name in drives]
    return table(header, rows)


STREET_ORACLE = "benchmarks/results/street_oracle.json"


def street_oracle_rows(drives: dict) -> list[tuple[str, str]]:
    """The (world, model) rows of ``street_oracle.json``'s ``drives``: the street world first, and
    in each world the preset's rows before the bandless odometry's."""
    worlds = sorted(drives["pooled"], key=lambda world: world != "street world")
    return [
        (world, model)
        for world in worlds
        for model in sorted(drives["pooled"][world], key=lambda model: model.startswith("odometry"))
    ]


def street_oracle() -> str:
    """The street preset, the preset with the camera's mounting known, on a level road and with
    its road tilt not measured by the speed, and its odometry without bands at the preset's
    attitude, at the true attitude against the road and at the true attitude on one axis at a
    time, on KITTI 09 and 10 in the street and the flat world."""
    rec = record(STREET_ORACLE)
    d, piece = rec["drives"], f"{rec['settings']['piece_m']:.0f} m"
    drives = [name for name in d if name != "pooled"]
    rows = []
    for world, model in street_oracle_rows(d):
        pooled = d["pooled"][world][model]
        cells = [num(d[name][world][model]["t_err_pct"], 2) for name in drives]
        cells += [num(pooled["t_err_pct"], 2), num(pooled["r_err_deg_per_100m"], 2)]
        cells += [
            f"{num(d[name][world][model]['distance_ratio'], 3)} / {num(d[name][world][model]['piece_scale_std'], 3)}"
            f" / {num(d[name][world][model]['along_cm'], 1)}"
            for name in drives
        ]
        rows.append([f"{world}: {model}"] + cells)
    header = ["world: model"] + [f"{name} t_err (%)" for name in drives] + ["pooled t_err (%)", "pooled r_err (deg/100 m)"]
    header += [f"{name}: distance ratio / {piece} pieces' spread / along the heading (cm)" for name in drives]
    return table(header, rows)


def street_oracle_projection() -> str:
    """How far the street preset's projection is from the true camera attitude against the road,
    and its filter's pitch from the truth's against gravity, on KITTI 09 and 10 in the street and
    the flat world (the bandless odometry's rows, projected at a given attitude, left out)."""
    d = record(STREET_ORACLE)["drives"]
    drives = [name for name in d if name != "pooled"]
    keys = ("projection_pitch_mean_deg", "projection_pitch_rmse_deg", "projection_roll_rmse_deg", "filter_pitch_rmse_deg")
    rows = [
        [f"{world}: {model}"] + [" / ".join(num(d[name][world][model][k], 2) for k in keys) for name in drives]
        for world, model in street_oracle_rows(d)
        if not model.startswith("odometry")
    ]
    header = ["world: model"] + [f"{name}: pitch mean / pitch RMS / roll RMS / filter's pitch RMS (deg)" for name in drives]
    return table(header, rows)


def street_oracle_slow_fast() -> str:
    """Per world, the pooled t_err of the bandless odometry at the true pitch plus the slow part of
    the preset's pitch error, plus its fast part, at the true pitch and at the preset's attitude."""
    d = record(STREET_ORACLE)["drives"]["pooled"]
    rows = {
        "the slow part": "odometry at the true pitch plus the preset's slow pitch error, the preset's roll",
        "the fast part": "odometry at the true pitch plus the preset's fast pitch error, the preset's roll",
        "no error (true pitch)": "odometry at the true pitch against the road, the preset's roll",
        "the whole error (the preset's attitude)": "odometry at the preset's attitude",
    }
    return "; ".join(
        f"{world}: " + ", ".join(f"{label} {d[world][model]['t_err_pct']:.2f} %" for label, model in rows.items())
        for world in ("street world", "flat world")
    )


BAND_SLOPE = "benchmarks/results/band_slope.json"


def _scatter_cells(v: dict) -> list[str]:
    """A ``band_slope.json`` scatter's median, robust scatter, standard deviation (degrees) and
    share beyond 1 degree (%)."""
    return [num(v[k], 3) for k in ("median_deg", "robust_scatter_deg", "std_deg")] + [num(100 * v["share_beyond_1_deg"], 1)]


def band_slope() -> str:
    """The bands' slope read as a pitch error and the full registration's forward motion over the
    true travel, per drive, with the pair projected at the true attitude against the road, with a
    pitch error both BEVs share and with the earlier BEV's pitch alone off."""
    d = record(BAND_SLOPE)["drives"]
    rows = [
        [f"{name}: {condition}", *_scatter_cells(v), num(v["forward_over_true_median"], 3)]
        for name, drive in d.items()
        for condition, v in sorted(drive["conditions"].items(), key=lambda item: (item[0] != "exact", item[0]))
    ]
    header = ["drive: BEV pair", "slope as pitch: median (deg)", "robust scatter (deg)", "std (deg)"]
    header += ["beyond 1 deg (%)", "forward motion / true (median)"]
    return table(header, rows)


def band_slope_confidence() -> str:
    """The slope's scatter at the true attitude per fifth of the pairs by DPC's confidence."""
    d = record(BAND_SLOPE)["drives"]
    rows = [
        [f"{name}: {num(b['confidence'][0], 2)}-{num(b['confidence'][1], 2)}", *_scatter_cells(b)]
        for name, drive in d.items()
        for b in drive["by_confidence"]
    ]
    header = ["drive: confidence", "median (deg)", "robust scatter (deg)", "std (deg)", "beyond 1 deg (%)"]
    return table(header, rows)


def _band_slope_responses(name: str, rec: dict, metric: str = "median_deg") -> tuple[float, float]:
    """How far ``metric`` moves (against the exact pair) for the shared offset and for the earlier
    BEV's alone, on drive ``name``."""
    c, offset = rec["drives"][name]["conditions"], rec["settings"]["offset_deg"]
    exact = c["exact"][metric]
    return c[f"both +{offset} deg"][metric] - exact, c[f"earlier +{offset} deg"][metric] - exact


def band_slope_tilt_change() -> str:
    """Per drive, the per-frame change of the road tilt (RMS over the frames, over the pairs, and
    of its 10-frame mean) and of the camera's pitch against the road."""
    d = record(BAND_SLOPE)["drives"]
    return "; ".join(
        f"{name}: {v['tilt']['road_tilt_change_rms_deg']:.3f} deg over the frames, {v['tilt']['road_tilt_change_rms_on_pairs_deg']:.3f}"
        f" over the pairs, {v['tilt']['road_tilt_change_10_frame_mean_rms_deg']:.3f} averaged over 10 frames (the camera's pitch"
        f" against the road: {v['tilt']['camera_pitch_change_rms_deg']:.3f} deg)"
        for name, v in d.items()
    )


def band_slope_phantom() -> str:
    """Per drive, the pitch error the slope reads from the road tilt's change over a pair: that
    change's RMS over the pairs times the slope's response per degree of the earlier BEV's pitch."""
    rec = record(BAND_SLOPE)
    offset = rec["settings"]["offset_deg"]
    parts = []
    for name, v in rec["drives"].items():
        per_degree = abs(_band_slope_responses(name, rec)[1]) / offset
        parts.append(f"{name}: {per_degree * v['tilt']['road_tilt_change_rms_on_pairs_deg']:.2f} deg")
    return ", ".join(parts)


def band_slope_response() -> str:
    """Per drive, how much the slope and the forward motion move for the shared offset and for the
    earlier BEV's alone (against the exact pair), the ratio of the two slope responses and the
    band model's."""
    rec = record(BAND_SLOPE)
    parts = []
    for name, v in rec["drives"].items():
        shared, alone = _band_slope_responses(name, rec)
        both, earlier = _band_slope_responses(name, rec, "forward_over_true_median")
        parts.append(
            f"{name}: slope {shared:+.3f} against {alone:+.3f} deg ({alone / shared:.1f} times; the band model"
            f" {v['model_ratio_median']:.1f}), forward motion {100 * both:+.1f} against {100 * earlier:+.1f} %"
        )
    return "; ".join(parts)


def street_oracle_uncoupled() -> str:
    """The street preset's pooled t_err against its road tilt's without the speed's share, per
    world, and the worst drive's of the latter."""
    d = record(STREET_ORACLE)["drives"]
    preset, ablation = "street + robust bands", "street + robust bands, tilt not measured by the speed"
    parts = []
    for world in ("street world", "flat world"):
        worst = max((name for name in d if name != "pooled"), key=lambda name: d[name][world][ablation]["t_err_pct"])
        parts.append(
            f"{world} {d['pooled'][world][preset]['t_err_pct']:.2f} % against {d['pooled'][world][ablation]['t_err_pct']:.2f} %"
            f" ({worst} alone: {d[worst][world][ablation]['t_err_pct']:.2f} %)"
        )
    return "; ".join(parts)


def kitti_street_scale() -> str:
    """The street preset's distance ratios on the street world's KITTI 09 and 10, with the camera
    mounted as the street world mounts it and as nominal."""
    d = record(STREET_DRIVES)["drives"]

    def ratios(world: str) -> str:
        return " and ".join(f"{d[name][world]['distance_ratio']:.3f} on {name}" for name in ("09", "10"))

    return f"{ratios('street world')}, and {ratios('street world, camera mounted as nominal')} with the camera mounted as nominal"


def real_kitti_keyframes_speed() -> str:
    speed = record(REAL_KITTI)["frames_per_s"]
    ratios = [v["street + robust bands, keyframes"] / v["street + robust bands"] for v in speed.values()]
    return f"{min(ratios):.2f}-{max(ratios):.2f}x"


#: The targets the real runs are read against: (label, metric, digits, bound, distance from 1
#: instead of the value).
REAL_TARGETS = (
    ("distance ratio within 1 ± 0.02", "distance_ratio", 3, 0.02, True),
    ("final error at most 2 %", "final_pct", 2, 2.0, False),
    ("motion RMSE at most 5 cm", "motion_cm", 1, 5.0, False),
    ("yaw RMSE at most 0.1 deg per frame", "yaw_deg", 3, 0.1, False),
    ("pitch/roll within 0.5 deg", "pitch_roll_max_deg", 2, 0.5, False),
)
#: The real runs and halves the targets hold on.
TARGET_RUNS = ("06", "06 second half", "07", "07 second half")


def real_kitti_targets() -> str:
    """Each target on the preset (``real_kitti.json``) and on the preset with forward fusion
    (``forward_fusion.json``), per whole run and second half: the value, and whether it is met."""
    models = (
        ("street + robust bands", record(REAL_KITTI)["runs"], "street + robust bands"),
        ("with forward fusion", record(FORWARD_FUSION)["runs"], "street + robust bands, forward fusion"),
    )
    rows = []
    for label, key, digits, bound, around_one in REAL_TARGETS:
        for model, runs, name in models:
            cells = []
            for run in TARGET_RUNS:
                value = runs[run][name][key]
                met = (abs(value - 1.0) if around_one else value) <= bound
                cells.append(f"{value:.{digits}f} ({'met' if met else 'missed'})")
            rows.append([f"{label}: {model}"] + cells)
    real, learned = models[0][1], "street + robust bands, learned"
    cells = []
    for run in TARGET_RUNS:
        if learned not in real[run]:
            cells.append("-")
            continue
        change = real[run][learned]["final_pct"] / real[run]["street + robust bands"]["final_pct"] - 1
        cells.append(f"{100 * change:+.0f} % ({'met' if change <= -0.3 else 'missed'})")
    rows.append(["learned final error at least 30 % below hand-set (mean of the seeds)"] + cells)
    return table(["target: model", "06", "06, 2nd half", "07", "07, 2nd half"], rows)


def real_kitti_learned() -> str:
    rec = record(REAL_KITTI)
    d, chosen = rec["learned_parameters"], rec["checkpoint_selection"]
    rows = []
    for run, labels in d.items():
        for label, halves in labels.items():
            for half, per_seed in halves.items():
                v = {k: [p[k] for p in per_seed] for k in per_seed[0]}
                rows.append(
                    [
                        f"{run}, {label}, {half}",
                        ", ".join(str(s["step"]) for s in chosen[run][label][half]),
                        spread(v["camera_pitch_deg"], 3),
                        spread(v["camera_roll_deg"], 3),
                        spread(v["height_scale"], 3),
                        spread(v["corridor_m"], 2),
                        spread(v["gyro_yaw_weight"], 3),
                        spread(v.get("road_tilt_walk_deg_per_sqrt_m", []), 4),
                    ]
                )
    header = [
        "learned on",
        "checkpoint per seed (step)",
        "camera pitch (deg)",
        "camera roll (deg)",
        "height scale",
        "corridor (m)",
        "gyro's yaw weight",
        "road tilt walk (deg/√m)",
    ]
    return table(header, rows)


# ----------------------------------------------------------------------------- the street world

STREET_WORLD = "benchmarks/results/street_world.json"


def _ratio_final(m: dict) -> str:
    return f"{m['distance_ratio']:.3f} / {m['final_pct']:.1f} %"


def street_world_signature() -> str:
    runs = record(STREET_WORLD)["runs"]
    models = ("BEVO, true attitude", "street + robust bands")
    header = ["world (distance ratio / final error)"] + [f"{run}: {model}" for model in models for run in ("06", "07")]
    rows = [
        [world] + [_ratio_final(runs[run][world][model]) for model in models for run in ("06", "07")]
        for world in sorted(runs["06"], key=lambda w: (w != "real frames", w == "flat world", w))
    ]
    return table(header, rows)


def street_world_models() -> str:
    runs = record(STREET_WORLD)["runs"]
    worlds = ("real frames", "street world", "flat world")
    header = ["model (distance ratio / final error)"] + [f"{run}, {world}" for run in ("06", "07") for world in worlds]
    rows = [
        [model] + [_ratio_final(runs[run][world][model]) for run in ("06", "07") for world in worlds]
        for model in runs["06"]["real frames"]
    ]
    return table(header, rows)


def street_world_zero_shot() -> str:
    d = record(STREET_WORLD)
    real = record(REAL_KITTI)["runs"]
    keys = ["06", "06 second half", "07", "07 second half"]
    seeds = d["settings"]["seeds"]
    rows = [
        ["street + robust bands, hand-set"] + [_metric(real[k]["street + robust bands"], "final_pct", 2) for k in keys],
        [f"street + robust bands, learned in the street world only ({seeds} seeds)"]
        + [_metric(d["zero_shot"][k], "final_pct", 2) for k in keys],
        [f"the same, the camera's calibration frozen ({seeds} seeds)"]
        + [_metric(d["zero_shot_calibration_frozen"][k], "final_pct", 2) for k in keys],
    ]
    for name in ("street + robust bands, learned",):
        rows.append(
            [f"{name} on the other half of the run (real_kitti.json)"]
            + [_metric(real[k].get(name), "final_pct", 2) for k in keys]
        )
    return table(["final error on the real frames (%)", "06", "06, 2nd half", "07", "07, 2nd half"], rows)


def street_world_keyframes() -> str:
    d = record(STREET_WORLD)["keyframes_check"]
    models = next(iter(d.values()))
    segments = ("whole", "first half", "second half")
    header = ["street-world drive (distance ratio / final error)"] + [f"{m}: {s}" for m in models for s in segments]
    rows = [[f"KITTI {drive}'s motion"] + [_ratio_final(d[drive][m][s]) for m in models for s in segments] for drive in d]
    return table(header, rows)


def street_world_minutes() -> str:
    return f"{record(STREET_WORLD)['seconds'] / 60:.0f}"


def street_world_zero_shot_parameters() -> str:
    p = record(STREET_WORLD)["zero_shot_parameters"]
    v = {k: [x[k] for x in p] for k in p[0]}
    return (
        f"camera pitch {spread(v['camera_pitch_deg'], 2)} deg, roll {spread(v['camera_roll_deg'], 2)} deg, "
        f"height scale {spread(v['height_scale'], 3)}"
    )


def street_world_zero_shot_steps() -> str:
    return ", ".join(str(c["step"]) for c in record(STREET_WORLD)["zero_shot_checkpoints"])


def street_world_zero_shot_frozen_gap() -> str:
    """The largest difference, in percentage points, between the frozen-calibration fit's final
    errors (means over the seeds) and the hand-set preset's on the zero-shot table's runs."""
    d = record(STREET_WORLD)["zero_shot_calibration_frozen"]
    real = record(REAL_KITTI)["runs"]
    keys = ["06", "06 second half", "07", "07 second half"]
    return f"{max(abs(d[k]['final_pct'] - real[k]['street + robust bands']['final_pct']) for k in keys):.3f}"


def street_world_zero_shot_frozen_steps() -> str:
    return ", ".join(str(c["step"]) for c in record(STREET_WORLD)["zero_shot_calibration_frozen_checkpoints"])


TABLES: dict[str, Callable[[], str]] = {
    "filtering_demo": filtering_demo,
    "ukf_speed": ukf_speed,
    "ukf_forms": ukf_forms,
    "ukf_blocked": ukf_blocked,
    "ukf_one_kernel": ukf_one_kernel,
    "forward_fusion": forward_fusion,
    "forward_fusion_sweep": forward_fusion_sweep,
    "forward_fusion_prior": forward_fusion_prior,
    "forward_fusion_street_world": forward_fusion_street_world,
    "forward_fusion_long": forward_fusion_long,
    "forward_fusion_held_out": forward_fusion_held_out,
    "forward_fusion_bias_sweep": forward_fusion_bias_sweep,
    "street_drives": street_drives,
    "street_oracle": street_oracle,
    "street_oracle_projection": street_oracle_projection,
    "band_slope": band_slope,
    "band_slope_confidence": band_slope_confidence,
    "parallel_in_time": parallel_in_time,
    "batch_last": batch_last,
    "attitude_synthetic": attitude_synthetic,
    "attitude_real": attitude_real,
    "attitude_real_headline": attitude_real_headline,
    "attitude_real_calibration": attitude_real_calibration,
    "attitude_euroc": attitude_euroc,
    "imu_noise_real": imu_noise_real,
    "registration_sets": registration_sets,
    "registration_peers": registration_peers,
    "bev_speed": bev_speed,
    "bevo_speed": bevo_speed,
    "simulator_speed": simulator_speed,
    "scaling_throughput": scaling_throughput,
    "scaling_memory": scaling_memory,
    "builtin_training": builtin_training,
    "bands": bands,
    "kitti_odometry": kitti_odometry,
    "kitti_validation": kitti_validation,
    "kitti_odometry_real_imu": lambda: kitti_odometry(KITTI_REAL_IMU),
    "kitti_validation_real_imu": lambda: kitti_validation(KITTI_REAL_IMU),
    "kitti_odometry_street": lambda: kitti_odometry(KITTI_STREET),
    "kitti_validation_street": lambda: kitti_validation(KITTI_STREET),
    "kitti_worlds": kitti_worlds,
    "kitti_training_sequences_street": kitti_training_sequences,
    "kitti_training_sequences_flat": lambda: kitti_training_sequences(KITTI_SIMULATED_IMU),
    "localization_carla_street": lambda: _localization("carla", LOCALIZATION_STREET),
    "localization_carla_street_preset": lambda: _localization("carla", LOCALIZATION_STREET_PRESET),
    "localization_carla": localization_carla,
    "localization_aeroground": localization_aeroground,
    "localization_validation": localization_validation,
    "localization_smoothing": localization_smoothing,
    "reference_metrics": reference_metrics,
    "real_kitti_headline": real_kitti_headline,
    "real_kitti_learned": real_kitti_learned,
    "real_kitti_targets": real_kitti_targets,
    "real_kitti_imu_dropouts": real_kitti_imu_dropouts,
    "imu_dropouts": imu_dropouts,
    "street_world_signature": street_world_signature,
    "street_world_models": street_world_models,
    "street_world_zero_shot": street_world_zero_shot,
    "street_world_keyframes": street_world_keyframes,
    **{
        f"real_kitti_{run.replace(' ', '_')}": (lambda run=run: real_kitti(run))
        for run in ("06", "06 first half", "06 second half", "07", "07 first half", "07 second half")
    },
}

VALUES: dict[str, Callable[[], str]] = {
    "imu_dropouts_truth_bend": imu_dropouts_truth_bend,
    "band_slope_tilt_change": band_slope_tilt_change,
    "street_oracle_slow_fast": street_oracle_slow_fast,
    "band_slope_phantom": band_slope_phantom,
    "band_slope_response": band_slope_response,
    "attitude_world_tilt": attitude_world_tilt,
    "ukf_agreement": ukf_agreement,
    "ukf_batch_last_vs_dynamax": ukf_batch_last_vs_dynamax,
    "ukf_compile": ukf_compile,
    "ukf_tria": ukf_tria,
    "localization_smoothing_summary": localization_smoothing_summary,
    "parallel_in_time_summary": parallel_in_time_summary,
    "ukf_cuthbertlib_agreement": ukf_cuthbertlib_agreement,
    "builtin_best_epochs": builtin_best_epochs,
    "builtin_wins": builtin_wins,
    "kitti_wins": kitti_wins,
    "kitti_wins_real_imu": lambda: kitti_wins(KITTI_REAL_IMU),
    "kitti_wins_street": lambda: kitti_wins(KITTI_STREET),
    "kitti_street_frames": lambda: str(record(KITTI_STREET)["frames_per_training_sequence"] or "all"),
    "localization_wins_street_preset": lambda: localization_wins(LOCALIZATION_STREET_PRESET),
    "localization_wins_street": lambda: localization_wins(LOCALIZATION_STREET),
    "localization_wins": localization_wins,
    "street_world_zero_shot_parameters": street_world_zero_shot_parameters,
    "street_world_zero_shot_steps": street_world_zero_shot_steps,
    "street_world_zero_shot_frozen_steps": street_world_zero_shot_frozen_steps,
    "street_world_zero_shot_frozen_gap": street_world_zero_shot_frozen_gap,
    "real_kitti_keyframes_speed": real_kitti_keyframes_speed,
    "kitti_street_scale": kitti_street_scale,
    "street_oracle_uncoupled": street_oracle_uncoupled,
    "street_world_minutes": street_world_minutes,
}
