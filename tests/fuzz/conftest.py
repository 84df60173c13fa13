"""Shared settings of the fuzz tests (issue 18): deterministic, at least 1,000 cases per reader.

``derandomize=True`` makes Hypothesis generate the same cases on every run and machine (no example
database, no random seed); ``FUZZ_EXAMPLES`` (environment) raises the count for a longer local run.
"""

import os

from hypothesis import HealthCheck, settings

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "1000"))

FUZZ = settings(
    max_examples=EXAMPLES,
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large],
    print_blob=True,
)
