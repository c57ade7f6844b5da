#!/usr/bin/env bash
# Regenerate every committed record (benchmarks/results/*.json, experiments/results/*.json), then
# the measured tables of the README and docs/ from them. Needs the bench extra
# (pip install -e ".[bench]") and the reference data ($JBEVO_REFERENCE_DATA); about six hours on
# a 2-core CPU. Timings are of this machine: run nothing else beside it.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
: "${JBEVO_REFERENCE_DATA:?set JBEVO_REFERENCE_DATA to the reference-data folder}"

python benchmarks/ukf.py
python benchmarks/parallel_in_time.py
python benchmarks/registration.py
python benchmarks/bev.py
python benchmarks/simulator.py
python benchmarks/bevo.py
python benchmarks/scaling.py
python benchmarks/attitude.py
python benchmarks/attitude_real.py
python benchmarks/imu_dropouts.py
python benchmarks/real_kitti.py
python benchmarks/street_world.py
python benchmarks/forward_fusion.py
python benchmarks/street_drives.py
python benchmarks/street_oracle.py
python benchmarks/band_slope.py
python experiments/filtering_demo.py
python experiments/reference_metrics.py
python experiments/bands.py
python experiments/builtin_training.py
python experiments/kitti_odometry.py
python experiments/kitti_odometry.py --real-imu
python experiments/kitti_odometry.py --world street --model street --frames 200  # the street preset learned
python experiments/localization.py
python experiments/localization.py --world street --kinds carla --seeds 0
python experiments/localization.py --world street --model street --kinds carla
python experiments/localization_smoothing.py
python docs/build.py
