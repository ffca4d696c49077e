import os

from hypothesis import settings

# Reproducible property tests in CI: fixed seed, no example database.
settings.register_profile("ci", derandomize=True, database=None, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
