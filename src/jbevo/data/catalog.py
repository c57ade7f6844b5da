"""The datasets the command lines offer, by name: ``synthetic`` (procedural drives in the
synthetic world), ``kitti-synthetic`` (the synthetic world driven by KITTI ground-truth motion)
and ``kitti`` (a KITTI odometry folder)."""

from __future__ import annotations

from pathlib import Path

from jbevo.data.kitti import check_imu_dropouts
from jbevo.data.sequence import Sequence
from jbevo.data.synthetic.sequences import builtin_dataset, kitti_sequence, small_camera
from jbevo.data.synthetic.street import Street, street_named
from jbevo.data.synthetic.world import World
from jbevo.geometry.camera import Camera
from jbevo.progress import progress

DATASETS = ("synthetic", "kitti-synthetic", "kitti")


def load_sequences(
    dataset: str,
    names: list[str],
    frames: int = 0,
    kitti_poses: Path | None = None,
    kitti_root: Path | None = None,
    camera: str = "small",
    town: str = "town01",
    seed: int = 0,
    kitti_imu: Path | None = None,
    positions: list[int] | None = None,
    world: str | Street | None = "flat",
    imu_dropouts: str = "published",
) -> list[Sequence]:
    """The sequences ``names`` of ``dataset``. For ``synthetic``, ``names`` are seeds (one
    procedural drive each, ``frames`` frames); for ``kitti-synthetic`` KITTI sequence names whose
    pose files are in ``kitti_poses`` (``frames`` caps the length, 0 = all; ``camera`` small or
    kitti; with ``kitti_imu``, the folder of the KITTI odometry IMU files, the real IMU, calibrated
    per recording day on 00-08, and frames rendered at the attitude it sees:
    :func:`jbevo.data.synthetic.sequences.kitti_sequence`; the drive at place ``i`` of the list is
    rendered with seed ``seed + i``, or ``seed + positions[i]`` where ``names`` is a share of a
    longer list); for ``kitti`` sequence names under ``kitti_root``. ``world`` is the synthetic
    world's kind (``flat`` or ``street``: :mod:`jbevo.data.synthetic.street`) or its
    :class:`~jbevo.data.synthetic.street.Street` settings (``None``: flat). ``imu_dropouts``: how
    the real IMU's dropouts are read (``published`` or ``missing``:
    :func:`jbevo.data.kitti.read_odometry`). ``ValueError`` names what is missing."""
    check_imu_dropouts(imu_dropouts)
    if imu_dropouts != "published" and kitti_imu is None:
        raise ValueError(f"imu_dropouts={imu_dropouts!r} needs kitti_imu, the real IMU whose dropouts it marks")
    street = street_named(world) if isinstance(world, str) else world
    if dataset == "synthetic":
        return [builtin_dataset(frames, 1, town, int(n), street)[0] for n in progress(names, "rendering synthetic drives")]
    if dataset == "kitti-synthetic":
        if kitti_poses is None:
            raise ValueError("the kitti-synthetic dataset needs kitti_poses, the folder of KITTI pose files NN.txt")
        from jbevo.data.pose_files import read_kitti
        from jbevo.inertial.kitti_imu import calibrated_drive

        ground = World.create(town)
        cam = small_camera() if camera == "small" else Camera.kitti()
        out = []
        places = range(len(names)) if positions is None else positions
        if len(places) != len(names):
            raise ValueError(f"{len(places)} positions for {len(names)} sequence names")
        for i, name in zip(places, progress(names, "rendering KITTI motion in the synthetic world")):
            path = Path(kitti_poses) / f"{name}.txt"
            if not path.is_file():
                raise ValueError(f"no KITTI pose file {path}")
            poses = read_kitti(path).poses
            n = min(frames, len(poses) - 1) if frames else None
            real = None if kitti_imu is None else calibrated_drive(kitti_poses, kitti_imu, name, imu_dropouts=imu_dropouts)
            out.append(kitti_sequence(poses, 0, n, camera=cam, world=ground, seed=seed + i, real_imu=real, street=street))
        return out
    if dataset == "kitti":
        if kitti_root is None:
            raise ValueError("the kitti dataset needs kitti_root, a KITTI odometry folder")
        from jbevo.data.kitti import read_odometry

        return [
            read_odometry(kitti_root, n, imu=kitti_imu, imu_dropouts=imu_dropouts)
            for n in progress(names, "reading KITTI sequences")
        ]
    raise ValueError(f"unknown dataset {dataset!r}; known: {DATASETS}")


__all__ = ["DATASETS", "load_sequences"]
