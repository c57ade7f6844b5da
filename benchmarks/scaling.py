"""How training and evaluation scale over devices and processes, and what the training windows
cost in memory.

    python benchmarks/scaling.py [--part throughput|memory|all] [--reference $JBEVO_REFERENCE_DATA]

``throughput``: the built-in synthetic drives (128 x 128 BEV), one process with 1, 2 and 4 devices
(on a CPU, host devices made by ``XLA_FLAGS=--xla_force_host_platform_device_count``, all sharing
its cores) and two processes of one job (``jax.distributed`` on localhost, one device each, gloo):
training frames/s (a batch of 4 windows of 16 frames split over the devices, the gradient averaged
across them: :mod:`jbevo.training.data_parallel`; best of the timed steps after the compiling one)
and inference frames/s (8 drives of 48 frames, the best of 3 runs, sharded over the devices, or
shared over the processes as ``python -m jbevo.evaluate`` shares them), with the compiled training step's memory
per device (XLA's memory analysis) and each process's peak RSS. Every configuration runs in its
own processes, one after the other. On an accelerator machine the device counts are its first 1,
2 and 4 accelerators, and the two processes need one accelerator each (each takes the devices it
sees).

``memory`` (needs the reference data): the KITTI-style run's training set (00-07 in the
synthetic world, 500 frames each, KITTI camera 0 at full size, windows of 96 frames every 48)
and one training step of BEVO with bands (batch 4), in a fresh process each for the windows
materialised as copies (every window's frames copied and the copies joined) and for :class:`jbevo.training.windows.Windows` (the drives held once, a batch sliced when
drawn): the peak RSS of each.

Writes ``benchmarks/results/scaling.json`` (the parts run; the other part's record is kept).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import socket
import subprocess
import sys
import time
from pathlib import Path

RESULT = Path(__file__).resolve().parent / "results" / "scaling.json"
CONFIGS = {  # name: (processes, devices per process)
    "1 device": (1, 1),
    "2 devices": (1, 2),
    "4 devices": (1, 4),
    "2 processes": (2, 1),
}
BATCH, WINDOW, TIMED_STEPS = 4, 16, 10
DRIVES, FRAMES = 8, 48
WORKER_TIMEOUT_S = 3600


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


# ----------------------------------------------------------------------------- workers


def throughput_worker(args: argparse.Namespace) -> None:
    """One process of a configuration: prints one JSON line."""
    if args.num_processes > 1:
        from jbevo.training import distributed

        distributed.initialize(f"localhost:{args.port}", args.num_processes, args.process_id)
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np
    import optax

    from jbevo.data.synthetic.sequences import builtin_dataset
    from jbevo.eval.batch import run_many
    from jbevo.models.bevo import Bevo
    from jbevo.models.losses import motion_loss
    from jbevo.training.data_parallel import DataParallel, local_copy
    from jbevo.training.distributed import gather_objects, share
    from jbevo.training.loop import make_step, take_batch
    from jbevo.training.windows import training_windows

    drives = builtin_dataset(FRAMES, DRIVES, "town01", 0)
    model = Bevo.create(args.grid, drives[0].imu_dt)
    # One process: its first --devices devices (host devices on a CPU, made by XLA_FLAGS; the
    # first N accelerators on a GPU machine). Several: every device of every process.
    devices = jax.devices()[: args.devices] if args.num_processes == 1 else jax.devices()
    if len(devices) < args.devices:
        raise SystemExit(f"{args.devices} devices asked for, {len(devices)} present")
    parallel = DataParallel.create(devices)

    # Training: the same batches in every configuration.
    windows = training_windows(drives, WINDOW, WINDOW)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    optimizer = optax.adam(1e-3)

    def loss(m, batch):
        out = jax.vmap(lambda q: m(q, warm_start=True))(batch)
        return jnp.mean(jax.vmap(motion_loss)(out, batch))

    step = make_step(static, optimizer, loss, parallel)
    params, opt_state = parallel.replicate((params, optimizer.init(params)))
    order = np.random.default_rng(0).permutation(len(windows))
    seconds = []
    for i in range(TIMED_STEPS + 1):
        idx = order[(i * BATCH) % (len(windows) - BATCH) :][:BATCH]
        t0 = time.perf_counter()
        batch = take_batch(windows, idx, parallel)
        params, opt_state, value = step(params, opt_state, batch)
        float(local_copy(value))
        seconds.append(time.perf_counter() - t0)
    lowered = step.lower(params, opt_state, batch)
    memory = lowered.compile().compiled.memory_analysis()  # equinox wraps jax.stages.Compiled
    step_bytes = None
    if memory is not None:
        step_bytes = memory.argument_size_in_bytes + memory.temp_size_in_bytes + memory.output_size_in_bytes

    # Inference: this process's share of the drives on its devices.
    mine = share(drives)
    t0 = time.perf_counter()
    local_devices = [d for d in devices if d.process_index == jax.process_index()]
    fps = max(run_many(model, mine, warm_start=True, devices=local_devices)[1] for _ in range(3))  # the best of 3
    local = {"frames": sum(q.num_frames for q in mine), "fps": fps, "peak_rss_mb": peak_rss_mb()}
    everyone = gather_objects(local)
    if jax.process_index() == 0:
        row = {
            "processes": jax.process_count(),
            "devices": parallel.size,
            "platform": jax.default_backend(),
            "train_frames_per_s": BATCH * WINDOW / min(seconds[1:]),
            "train_compile_and_first_step_s": seconds[0],
            # The processes run their shares at once: frames over the slowest one's time.
            "inference_frames_per_s": sum(p["frames"] for p in everyone) / max(p["frames"] / p["fps"] for p in everyone),
            "train_step_memory_per_device_mb": step_bytes / 2**20 if step_bytes is not None else None,
            "peak_rss_mb_per_process": [p["peak_rss_mb"] for p in everyone],
            "final_loss": float(local_copy(value)),
        }
        print("RESULT " + json.dumps(row), flush=True)


def memory_worker(args: argparse.Namespace) -> None:
    """The KITTI-style training set and one step, with ``args.windows`` ("copies" or "indices")."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np
    import optax

    from jbevo.data import sequence as sq
    from jbevo.data.catalog import load_sequences
    from jbevo.geometry.bev_grid import BevGrid
    from jbevo.models.bevo import Bevo
    from jbevo.models.losses import motion_loss
    from jbevo.training.loop import make_step, take_batch
    from jbevo.training.windows import training_windows

    t0 = time.perf_counter()
    names = [f"{i:02d}" for i in range(8)]
    poses = args.reference / "kitti_odom" / "gt_poses"
    seqs = load_sequences("kitti-synthetic", names, args.frames, poses, None, "kitti", seed=0)
    after_loading = peak_rss_mb()
    drive_bytes = sum(int(np.asarray(q.images).nbytes) for q in seqs)
    if args.windows == "copies":  # materialised: copies, then joined
        parts = [sq.windows(q, args.window, args.window // 2) for q in seqs if q.num_frames >= args.window]
        windows = jax.tree_util.tree_map(lambda *x: jnp.concatenate(x), *parts)
        del parts
        count = int(windows.images.shape[0])
        window_bytes = int(windows.images.nbytes)
    else:
        windows = training_windows(seqs, args.window)
        count, window_bytes = len(windows), 0
    del seqs
    model = Bevo.create(BevGrid(0.1, (256, 256), near=4.0), 0.01, bands=True)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    optimizer = optax.adam(1e-3)

    def loss(m, batch):
        out = jax.vmap(lambda q: m(q, warm_start=True))(batch)
        return jnp.mean(jax.vmap(motion_loss)(out, batch))

    step = make_step(static, optimizer, loss)
    idx = np.random.default_rng(0).permutation(count)[:4]
    _, _, value = step(params, optimizer.init(params), take_batch(windows, idx))
    row = {
        "windows": args.windows,
        "window_count": count,
        "drive_images_gb": drive_bytes / 2**30,
        "window_copies_gb": window_bytes / 2**30,
        "peak_rss_after_loading_gb": after_loading / 2**10,
        "peak_rss_gb": peak_rss_mb() / 2**10,
        "loss": float(value),
        "seconds": time.perf_counter() - t0,
    }
    print("RESULT " + json.dumps(row), flush=True)


# ----------------------------------------------------------------------------- driver


def _result(stdout: str) -> dict:
    lines = [line for line in stdout.splitlines() if line.startswith("RESULT ")]
    return json.loads(lines[-1][len("RESULT ") :])


def run_throughput(config: str) -> dict:
    processes, devices = CONFIGS[config]
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"} | {"JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "")}
    if not env["JAX_PLATFORMS"]:
        env.pop("JAX_PLATFORMS")
    if devices > 1:  # host devices on a CPU (an accelerator machine has its own)
        env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={devices}"
    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    cmd = [sys.executable, __file__, "--worker", "throughput", "--num-processes", str(processes), "--port", str(port)]
    cmd += ["--devices", str(devices)]
    procs = [
        subprocess.Popen([*cmd, "--process-id", str(i)], env=env, stdout=subprocess.PIPE, text=True) for i in range(processes)
    ]
    try:
        outs = [p.communicate(timeout=WORKER_TIMEOUT_S)[0] for p in procs]
    except subprocess.TimeoutExpired:
        for p in procs:
            p.kill()
        raise RuntimeError(f"{config}: a worker ran past {WORKER_TIMEOUT_S} s") from None
    if any(p.returncode for p in procs):
        raise RuntimeError(f"{config}: a worker failed")
    row = _result(outs[0])
    print(f"{config}: train {row['train_frames_per_s']:.1f} frames/s, inference {row['inference_frames_per_s']:.1f} frames/s")
    return row


def run_memory(reference: Path, windows: str, frames: int, window: int) -> dict:
    cmd = [sys.executable, __file__, "--worker", "memory", "--windows", windows, "--reference", str(reference)]
    out = subprocess.run(
        [*cmd, "--frames", str(frames), "--window", str(window)],
        stdout=subprocess.PIPE,
        text=True,
        check=True,
        timeout=WORKER_TIMEOUT_S,
    )
    row = _result(out.stdout)
    print(f"windows as {windows}: peak RSS {row['peak_rss_gb']:.2f} GB ({row['seconds']:.0f} s)")
    return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--part", choices=("throughput", "memory", "all"), default="all")
    p.add_argument("--reference", type=Path, default=os.environ.get("JBEVO_REFERENCE_DATA"))
    p.add_argument("--frames", type=int, default=500, help="memory: frames per KITTI-style training sequence")
    p.add_argument("--window", type=int, default=96, help="memory: training window (frames)")
    p.add_argument("--out", type=Path, default=RESULT)
    p.add_argument("--worker", choices=("throughput", "memory"), help=argparse.SUPPRESS)
    p.add_argument("--windows", choices=("copies", "indices"), help=argparse.SUPPRESS)
    p.add_argument("--num-processes", type=int, default=1, help=argparse.SUPPRESS)
    p.add_argument("--process-id", type=int, default=0, help=argparse.SUPPRESS)
    p.add_argument("--port", type=int, default=0, help=argparse.SUPPRESS)
    p.add_argument("--devices", type=int, default=1, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker == "throughput":
        from jbevo.geometry.bev_grid import BevGrid

        args.grid = BevGrid(0.1, (128, 128), near=7.5)
        throughput_worker(args)
        return 0
    if args.worker == "memory":
        memory_worker(args)
        return 0

    record = json.loads(args.out.read_text()) if args.out.is_file() else {}
    record["machine"] = {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version()}
    if args.part in ("throughput", "all"):
        rows = {config: run_throughput(config) for config in CONFIGS}
        base = rows["1 device"]
        for row in rows.values():
            row["train_speedup"] = row["train_frames_per_s"] / base["train_frames_per_s"]
            row["inference_speedup"] = row["inference_frames_per_s"] / base["inference_frames_per_s"]
            # The same four steps on the same batches: equal to round-off.
            row["final_loss_relative_difference"] = abs(row["final_loss"] / base["final_loss"] - 1)
        record["throughput"] = {
            "workload": {"batch": BATCH, "window": WINDOW, "timed_steps": TIMED_STEPS, "drives": DRIVES, "frames": FRAMES},
            "configs": rows,
        }
    if args.part in ("memory", "all"):
        if args.reference is None:
            sys.exit("the memory part needs --reference (the shared data folder) or JBEVO_REFERENCE_DATA")
        rows = {w: run_memory(args.reference, w, args.frames, args.window) for w in ("copies", "indices")}
        record["memory"] = {
            "workload": {
                "sequences": "00-07",
                "frames": args.frames,
                "window": args.window,
                "stride": args.window // 2,
                "batch": 4,
            },
            "rows": rows,
            "peak_rss_ratio": rows["copies"]["peak_rss_gb"] / rows["indices"]["peak_rss_gb"],
        }
    from jbevo.files import write_json_atomic

    write_json_atomic(args.out, record)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
