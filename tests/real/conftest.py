"""Shared paths for the real-geometry tests (data: tests/data/rpc and assets/dem, see their PROVENANCE.md)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RPC_DIR = ROOT / "tests" / "data" / "rpc"
DEM_DIR = ROOT / "assets" / "dem"
PHR_2017 = RPC_DIR / "PHRDIMAP_P1BP--2017030824934340CP.XML"
PHR_2018 = RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML"
WV1 = RPC_DIR / "rpc_WV1.xml"
