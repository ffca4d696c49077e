"""IMU emulator: a described motion becomes what a real IMU would put on the wire.

Python API:
    scene = load_scene("examples/helix.toml")      # or scene_from_dict({...})
    samples = simulate(scene)                      # SampleBlock: t_s, accel, gyro (n_imu, n, 3), quat
    sim = Simulation(scene); sim.block(k0, n)      # block-wise, for long or live runs

The package's layers, in the order data flows (docs/architecture.md; the import contract in
pyproject.toml checks that imports run this one way):
    scene -> motion -> codegen -> runtime -> output -> live -> analysis -> commands -> cli
with companions (sensors beside the IMU's triads, which scene validation reads and runtime runs), effects, geo,
numerics, native, files, extensions and errors as leaves any layer may use.
"""
from imu_emulator.errors import DataError, ImuEmulatorError, SceneError, TargetError

# Where each public name lives. Imported on first use: firmware_protocols imports imu_emulator.native (its
# encoders' machine code) and must not pull in scene validation; Simulation pulls in numba.
_API = {
    "SampleBlock": "imu_emulator.runtime.samples",
    "Scene": "imu_emulator.scene.model",
    "load_scene": "imu_emulator.scene.load",
    "scene_from_dict": "imu_emulator.scene.load",
    "Simulation": "imu_emulator.runtime.simulation",
    "simulate": "imu_emulator.runtime.simulation",
}


def _version() -> str:
    """The installed distribution's version: pyproject.toml writes it once, the metadata carries it (read only
    when asked: importlib.metadata costs ~10 ms of start-up)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("imu-emulator")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed)"


def __getattr__(name):
    if name == "__version__":
        return _version()
    if name in _API:
        import importlib
        module = importlib.import_module(_API[name])
        return getattr(module, "from_dict" if name == "scene_from_dict" else name)
    raise AttributeError(f"module 'imu_emulator' has no attribute {name!r}")


__all__ = ["__version__", "DataError", "ImuEmulatorError", "SampleBlock", "Scene", "SceneError", "Simulation",
           "TargetError", "load_scene", "scene_from_dict", "simulate"]
