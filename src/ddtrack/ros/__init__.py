"""ROS 2 in and out, with no ROS installation (the pure-Python ``rosbags``): a run exported as a bag that Foxglove
and ``ros2 bag`` open, and a reference imported from a bag (docs/ros.md)."""

from .export import COLUMN_UNITS, Export, check_target, export_run, write_bag
from .references import ImportedReference, reference_from_odometry, reference_from_path, write_reference_csv

__all__ = [
    "COLUMN_UNITS",
    "Export",
    "ImportedReference",
    "check_target",
    "export_run",
    "reference_from_odometry",
    "reference_from_path",
    "write_bag",
    "write_reference_csv",
]
