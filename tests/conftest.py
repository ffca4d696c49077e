import os

from hypothesis import settings

# Reproducible property tests in CI: fixed seed, no example database.
settings.register_profile("ci", derandomize=True, database=None, deadline=None, print_blob=True)
# Longer searches on demand (HYPOTHESIS_PROFILE=fuzz, with FUZZ_EXAMPLES=N for tests/scene/test_scene_fuzz.py):
# random seeds, failures printed with a blob to reproduce them.
settings.register_profile("fuzz", database=None, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
