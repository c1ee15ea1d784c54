"""ROS 2 in and out, with no ROS installation (the pure-Python ``rosbags``): a run exported as a bag that Foxglove
and ``ros2 bag`` open, a reference imported from a bag, and topics live over DDS (``ddtrack[ros]``; docs/ros.md)."""

from .dds import DEFAULT_QOS, SENSOR_DATA_QOS, TF_STATIC_QOS, Participant, Publisher, QosProfile, Subscriber
from .export import COLUMN_UNITS, Export, check_target, export_run, write_bag
from .references import ImportedReference, reference_from_odometry, reference_from_path, write_reference_csv

__all__ = [
    "COLUMN_UNITS",
    "DEFAULT_QOS",
    "SENSOR_DATA_QOS",
    "TF_STATIC_QOS",
    "Export",
    "ImportedReference",
    "Participant",
    "Publisher",
    "QosProfile",
    "Subscriber",
    "check_target",
    "export_run",
    "reference_from_odometry",
    "reference_from_path",
    "write_bag",
    "write_reference_csv",
]
