"""Where the shared datasets live: ../shared/data beside the repository, read in place (never
copied in). Tests that need one skip when it is absent."""

from pathlib import Path

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
