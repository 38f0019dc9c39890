"""The LiDAR stage: everything done to the sweeps before any image is compared with them.

* :mod:`~paretocal.lidar.rings`: the laser rings of a spinning LiDAR, read from the file or
  recovered from the geometry (the line model of each laser's cone), with their purity;
* :mod:`~paretocal.lidar.sensor`: the sensor's pose in the cloud's frame (a vehicle frame),
  from the rings and the ground;
* :mod:`~paretocal.lidar.trajectory`: the motions a sweep can be de-skewed with (a constant twist,
  a pose trajectory), the SE(3) algebra they use, and de-skewing to one time;
* :mod:`~paretocal.lidar.registration`: one rigid cloud registered onto another (robust
  point-to-plane ICP) with the information and covariance of the solution;
* :mod:`~paretocal.lidar.motion`: the ego-motion of a sequence of sweeps, its observability,
  and the time offset between the points' clock and the sweeps'.

Pure functions over arrays: nothing here reads a file or draws. The pipeline's LiDAR steps
(:func:`paretocal.inputs.prepare_lidar`) call them in this order: sensor pose, rings, motion.
"""

from .trajectory import Motion, PoseTrajectory, Twist, deskew, sweep_centre
from .motion import (MotionEstimate, TimeOffsetEstimate, estimate_motion, estimate_time_offset,
                     pair_residuals)
from .registration import PairRegistration, register_pair
from .rings import Rings, recover_rings
from .sensor import estimate_sensor_pose

__all__ = ["Motion", "MotionEstimate", "PairRegistration", "PoseTrajectory", "Rings",
           "TimeOffsetEstimate", "Twist", "deskew", "estimate_motion", "estimate_sensor_pose",
           "estimate_time_offset", "pair_residuals", "recover_rings", "register_pair",
           "sweep_centre"]
