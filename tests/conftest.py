import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REAL_HARP = Path(os.environ.get("HARP_REAL_DATA", REPO.parent / "shared" / "data" / "real-harp"))


@pytest.fixture(scope="session")
def real_harp_dir() -> Path:
    if not REAL_HARP.is_dir():
        pytest.fail(f"real harp photos not found at {REAL_HARP} (set HARP_REAL_DATA)")
    return REAL_HARP
