"""Default sizes of the benchmark protocol (standard library only: the command line's parser reads them)."""

from __future__ import annotations

#: SCOP counts of the papers' protocol (learned methods are fitted on each).
DEFAULT_SCOPS: tuple[int, ...] = (10, 30, 50, 100)
#: SCPs per scene (the papers' 5,000,000 check points).
DEFAULT_SCPS = 5_000_000
#: Subsample size for methods that spend up to one collinearity evaluation per image row and point.
DEFAULT_MAX_POINTS_SLOW = 20_000
#: Subsample any method whose projected time exceeds this many seconds.
DEFAULT_SLOW_SECONDS = 60.0
