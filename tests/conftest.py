import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

REPO = Path(__file__).resolve().parents[1]
EC66 = REPO / "urdf" / "ec66.urdf"
SHARED = REPO.parent / "shared"
TIAGO_DIR = SHARED / "data" / "tiago_mocap"
TIAGO_URDF = TIAGO_DIR / "tiago_48_schunk.urdf"


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def tiago_urdf():
    if not TIAGO_URDF.exists():
        pytest.skip("../shared/data/tiago_mocap is not present")
    return TIAGO_URDF


def random_joint_values(geometry, rng, n):
    lo = np.where(np.isfinite(geometry.lower), geometry.lower, -np.pi)
    hi = np.where(np.isfinite(geometry.upper), geometry.upper, np.pi)
    return rng.uniform(lo, hi, size=(n, geometry.n))


def ur10_path() -> Path:
    """The UR10 URDF of the installed example-robot-data (located by kincal itself)."""
    from kincal.descriptions import resolve
    from kincal.errors import InputFileError

    try:
        return resolve("ur10").urdf
    except InputFileError:
        pytest.skip("example-robot-data is not installed")
