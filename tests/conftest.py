"""Shared fixtures: the bundled robots, loaded once per session."""

from __future__ import annotations

import numpy as np
import pytest

import wholebody


@pytest.fixture(scope="session")
def humanoid() -> wholebody.Robot:
    return wholebody.load_robot("mobile_humanoid")


@pytest.fixture(scope="session")
def torso() -> wholebody.Robot:
    return wholebody.load_robot("dual_arm_torso")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20241216)
