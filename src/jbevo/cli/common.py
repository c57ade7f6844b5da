"""What every command line shares: the parent parsers of the options they have in common, and
one exit-code convention.

* ``0``: done.
* ``2``: a usage error (an unknown option, a value of the wrong type or range): argparse's
  message and the usage line.
* ``1``: bad input data (a missing file or folder, a malformed or incompatible file): one line
  ``prog: error: ...`` naming what is wrong, no traceback. Only the code that reads inputs is
  wrapped (:func:`reading`), so an error anywhere else is a bug and shows its traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from jbevo.data.catalog import DATASETS
from jbevo.data.kitti import IMU_DROPOUTS
from jbevo.data.synthetic.street import WORLDS
from jbevo.data.synthetic.world import TOWNS
from jbevo.geometry.bev_grid import BevGrid
from jbevo.models.bevo import Bevo
from jbevo.models.presets import street_model
from jbevo.training.loop import TrainingDiverged, load_best


class CommandError(Exception):
    """Bad input that a command reports in one line and exit code 1."""


@contextlib.contextmanager
def reading(what: str) -> Iterator[None]:
    """Turn the errors of reading ``what`` (``ValueError``, ``OSError``, ``FileNotFoundError``)
    into a :class:`CommandError`."""
    try:
        yield
    except (ValueError, OSError) as error:
        raise CommandError(f"{what}: {error}") from None


@contextlib.contextmanager
def diverged_as_command_error() -> Iterator[None]:
    """Turn a training run whose loss stopped being finite into a :class:`CommandError` (it names
    the epoch and the step, and what to change)."""
    try:
        yield
    except TrainingDiverged as error:
        raise CommandError(str(error)) from None


@contextlib.contextmanager
def together() -> Iterator[None]:
    """Run a block that may fail on some processes of a job only (reading one host's files): a
    :class:`CommandError` on any process becomes one on every process, naming the failing one,
    so that none is left waiting in a collective. In a single process, just the block."""
    from jbevo.training import distributed

    error = None
    try:
        yield
    except CommandError as e:
        error = str(e)
    try:
        distributed.agree(error)
    except RuntimeError as e:
        raise CommandError(str(e)) from None


def check_batch(parallel, batch: int, windows: int) -> None:
    """A :class:`CommandError` unless the batches of ``batch`` windows drawn from ``windows``
    (a single short one when there are fewer) split evenly over ``parallel``'s devices."""
    if windows < 1:
        raise CommandError("there is no training window")
    try:
        parallel.check_batch(min(batch, windows))
    except ValueError as error:
        short = f" (the training set holds {windows} windows, fewer than --batch {batch})" if windows < batch else ""
        raise CommandError(f"--batch: {error}{short}") from None


def best_checkpoint(out: Path):
    """The model of ``out/best.ckpt`` and its epoch (:func:`jbevo.training.loop.load_best`); says
    so when it holds the hand-set parameters."""
    with reading(f"{out / 'best.ckpt'}"):
        model, epoch = load_best(out)
    if epoch == 0:
        print("no epoch validated better than the hand-set parameters: best.ckpt holds them")
    return model, epoch


def require_imu(seqs: Sequence, names: Sequence[str], attitude: str, alternative: str = "") -> None:
    """Refuse to run an attitude source that reads the IMU (``filter``, ``accel``) on sequences
    without IMU samples (a KITTI odometry folder read without ``--kitti-imu``), instead of
    filtering zeros; ``alternative`` names another way out (e.g. an ``--attitude`` choice)."""
    from jbevo.data.kitti import has_imu

    if attitude not in ("filter", "accel"):
        return
    missing = [n for n, q in zip(names, seqs) if not has_imu(q)]
    if missing:
        raise CommandError(
            f"sequence{'s' if len(missing) > 1 else ''} {', '.join(missing)} hold{'' if len(missing) > 1 else 's'} no IMU "
            f"samples, which the {attitude!r} attitude needs: pass --kitti-imu DIR (the KITTI odometry IMU files NN.mat)"
            + (f" or {alternative}" if alternative else "")
        )


def run(parser: argparse.ArgumentParser, command: Callable[[argparse.Namespace], object], argv: Sequence[str] | None) -> int:
    """Parse ``argv`` (exit 2 on a usage error) and run ``command``; a :class:`CommandError`
    prints ``prog: error: message`` and gives 1."""
    args = parser.parse_args(argv)
    stdout = sys.stdout
    try:
        result = command(args)
    except CommandError as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 1
    finally:
        if sys.stdout is not stdout:  # a process of a job other than 0 (join_job)
            sys.stdout.close()
            sys.stdout = stdout
    return result if isinstance(result, int) else 0


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def non_negative_int(text: str) -> int:
    """An argparse type: an integer >= 0."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a number > 0."""
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {value}")
    return value


class GridAction(argparse.Action):
    """``--grid RES SIZE NEAR``: metres per pixel (float > 0), pixels per side (int >= 16) and
    the nearest distance covered (metres, float); stored as a :class:`BevGrid`."""

    def __call__(self, parser, namespace, values, option_string=None):
        res, size, near = list(values or ())
        try:
            resolution, pixels, nearest = float(res), int(size), float(near)
        except ValueError:
            parser.error(
                f"{option_string} takes RES (metres per pixel), SIZE (whole pixels) and NEAR (metres), got {res} {size} {near}"
            )
        if not resolution > 0 or pixels < 16:
            parser.error(f"{option_string} needs RES > 0 and SIZE >= 16, got {res} and {size}")
        setattr(namespace, self.dest, BevGrid(resolution, (pixels, pixels), near=nearest))


def grid_option(default: BevGrid) -> argparse.ArgumentParser:
    """A parent parser with ``--grid RES SIZE NEAR`` (the BEV)."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument(
        "--grid",
        nargs=3,
        action=GridAction,
        default=default,
        metavar=("RES", "SIZE", "NEAR"),
        help="BEV: metres per pixel, pixels per side, nearest metres ahead",
    )
    return p


def dataset_options(default_frames: int) -> argparse.ArgumentParser:
    """A parent parser with the options that choose and load a dataset (:mod:`jbevo.data.catalog`)."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--dataset", choices=DATASETS, default="synthetic")
    p.add_argument("--kitti-poses", type=Path, help="folder of KITTI pose files NN.txt (kitti-synthetic)")
    p.add_argument("--kitti-root", type=Path, help="KITTI odometry root folder (kitti)")
    p.add_argument(
        "--kitti-imu",
        type=Path,
        help="folder of the KITTI odometry IMU files NN.mat (kitti, kitti-synthetic): the real IMU the attitude filter runs on",
    )
    p.add_argument(
        "--imu-dropouts",
        choices=IMU_DROPOUTS,
        default="published",
        help="the real IMU's dropouts: as the files fill them (straight lines) or marked missing",
    )
    p.add_argument(
        "--frames",
        type=non_negative_int,
        default=default_frames,
        help="frames per sequence (synthetic; a cap for kitti-synthetic, 0 = all)",
    )
    p.add_argument("--town", choices=sorted(TOWNS), default="town01", help="synthetic world")
    p.add_argument(
        "--world",
        choices=sorted(WORLDS),
        default="flat",
        help="synthetic world kind: flat (a level textured plane) or street (structures, slopes, camera mounting, exposure)",
    )
    p.add_argument("--camera", choices=("small", "kitti"), default="small", help="kitti-synthetic camera: 128x416 or 376x1241")
    return p


MODELS = ("bevo", "street")


def model_option() -> argparse.ArgumentParser:
    """A parent parser with ``--model`` (BEVO as the paper has it, or the street preset) and
    ``--forward-fusion``."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument(
        "--model",
        choices=MODELS,
        default="bevo",
        help="bevo (the paper's model) or street (jbevo.models.presets.street_model: camera against the road, road "
        "corridor, the gyro's turn fused with DPC's; with --bands the robust bands on the road's grade)",
    )
    p.add_argument(
        "--forward-fusion",
        action="store_true",
        help="hand-set model with the forward motion fused from the accelerometer and DPC "
        "(jbevo.models.forward_fusion; a checkpoint brings its own)",
    )
    return p


def hand_set_model(
    kind: str, grid: BevGrid, imu_dt: float, bands: bool, attitude: str = "filter", forward_fusion: bool = False
) -> Bevo:
    """The hand-set model of ``--model`` on ``grid``, with or without the band geometry and the
    forward fusion."""
    if kind == "street":
        model = street_model(imu_dt, grid, bands=bands, forward_fusion=forward_fusion)
        return dataclasses.replace(model, attitude_source=attitude)
    return Bevo.create(grid, imu_dt, attitude, bands=bands, forward_fusion=forward_fusion)


def seed_option(default: int = 0, help: str = "random seed") -> argparse.ArgumentParser:
    """A parent parser with ``--seed``."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--seed", type=int, default=default, help=help)
    return p


def optimizer_options(lr: float, epochs: int, window: int, batch: int, whole: bool = False) -> argparse.ArgumentParser:
    """A parent parser with the training loop's options (:mod:`jbevo.training.loop`); with
    ``whole``, ``--window 0`` trains on whole sequences."""
    p = argparse.ArgumentParser(add_help=False)
    if whole:
        p.add_argument(
            "--window", type=non_negative_int, default=window, help="training window length (frames; 0: whole sequences)"
        )
    else:
        p.add_argument("--window", type=positive_int, default=window, help="training window length (frames)")
    p.add_argument("--batch", type=positive_int, default=batch, help="windows per step (vmapped)")
    p.add_argument("--epochs", type=positive_int, default=epochs)
    p.add_argument("--lr", type=positive_float, default=lr, help="Adam learning rate (the parameters are logs)")
    p.add_argument("--clip", type=positive_float, default=1.0, help="global gradient-norm clip")
    p.add_argument("--yaw-weight", type=positive_float, default=10.0, help="metres per radian of yaw error in the loss")
    p.add_argument("--resume", action="store_true", help="continue from OUT/last.ckpt")
    return p


def distributed_options() -> argparse.ArgumentParser:
    """A parent parser with the options that make a command one process of several
    (:mod:`jbevo.training.distributed`)."""
    p = argparse.ArgumentParser(add_help=False)
    g = p.add_argument_group(
        "several processes (one per host or accelerator; jax.distributed)",
        "with --distributed alone, JAX reads the coordinator, the process count and id from its "
        "environment (JAX_COORDINATOR_ADDRESS) or the cluster (SLURM, Open MPI, Kubernetes)",
    )
    g.add_argument("--distributed", action="store_true", help="join a job of several processes")
    g.add_argument("--coordinator", metavar="HOST:PORT", help="process 0's address (implies --distributed)")
    g.add_argument("--num-processes", type=positive_int, help="how many processes the job has (implies --distributed)")
    g.add_argument("--process-id", type=non_negative_int, help="this process's index, from 0 (implies --distributed)")
    return p


def join_job(args: argparse.Namespace) -> None:
    """Join the job of several processes that ``args`` asks for (:func:`distributed_options`);
    nothing otherwise. Only process 0 prints to stdout afterwards."""
    from jbevo.training import distributed

    if not (args.distributed or args.coordinator or args.num_processes is not None or args.process_id is not None):
        return
    try:
        distributed.initialize(args.coordinator, args.num_processes, args.process_id)
    except (ValueError, RuntimeError) as error:
        raise CommandError(f"joining the job of several processes: {error}") from None
    if not distributed.is_main():
        sys.stdout = open(os.devnull, "w")  # until the command ends (run restores it)


def parser(prog: str, doc: str | None, parents: Sequence[argparse.ArgumentParser] = ()) -> argparse.ArgumentParser:
    """A command's parser: ``prog``, the module docstring as description, the parent parsers."""
    return argparse.ArgumentParser(
        prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter, parents=list(parents)
    )


def json_args(args: argparse.Namespace) -> dict:
    """The parsed options as JSON values (paths and grids as text)."""
    out = {}
    for key, value in vars(args).items():
        if callable(value):
            continue
        if isinstance(value, BevGrid):
            value = {"resolution": value.resolution, "shape": list(value.shape), "origin": list(value.origin)}
        elif isinstance(value, Path):
            value = str(value)
        out[key] = value
    return out


__all__ = [
    "CommandError",
    "GridAction",
    "best_checkpoint",
    "check_batch",
    "dataset_options",
    "hand_set_model",
    "model_option",
    "distributed_options",
    "diverged_as_command_error",
    "grid_option",
    "join_job",
    "json_args",
    "non_negative_int",
    "optimizer_options",
    "parser",
    "positive_float",
    "positive_int",
    "reading",
    "run",
    "seed_option",
    "together",
]
