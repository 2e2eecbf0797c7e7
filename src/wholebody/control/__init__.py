"""The control loop, run logs and their metrics."""

from __future__ import annotations

from wholebody.control.controller import Controller, ReferenceTask
from wholebody.control.log import ArmTrace, RunLog
from wholebody.control.metrics import (
    Tracking,
    closed_chain_error,
    limit_violations,
    summary,
    tracking,
)
from wholebody.control.recovery import Retreat, StallRecovery, mid_range_posture
from wholebody.control.sensor import JointSensor, SensorReadout

__all__ = [
    "ArmTrace",
    "Controller",
    "JointSensor",
    "ReferenceTask",
    "Retreat",
    "RunLog",
    "SensorReadout",
    "StallRecovery",
    "Tracking",
    "closed_chain_error",
    "limit_violations",
    "mid_range_posture",
    "summary",
    "tracking",
]
