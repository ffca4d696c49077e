"""What a file records about the run that made it (Parquet's footer, MCAP's metadata record): the scene's
digest and seed, its time base and IMUs, and the versions whose code shaped the samples."""
from __future__ import annotations

import platform
from functools import lru_cache


@lru_cache(maxsize=1)
def versions() -> dict[str, str]:
    """The versions whose code shaped the samples (read once per process: a batch writes many files)."""
    # here, not at the top: importlib.metadata pulls in email, csv and zipfile, and every command that finds the
    # output formats (check, generate) imports this module
    from importlib import metadata as importlib_metadata
    found = {"python": platform.python_version()}
    for package in ("imu-emulator", "numpy", "numba", "pyarrow", "mcap"):
        try:
            found[package] = importlib_metadata.version(package)
        except importlib_metadata.PackageNotFoundError:
            found[package] = "unknown"
    return found


def run_metadata(scene, **extra) -> dict:
    """What a file records about the run that made it."""
    from imu_emulator.scene.digest import scene_digest
    return {"scene_sha256": scene_digest(scene), "scene_path": scene.path, "seed": scene.seed,
            "rate_hz": scene.rate_hz, "t0_s": scene.t0_s, "n_samples": scene.n_samples,
            "imu_names": list(scene.imu_names), "frame": scene.frame, "versions": dict(versions()), **extra}
