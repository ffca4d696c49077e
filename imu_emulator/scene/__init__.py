"""Scene: a TOML file or a dict becomes a validated, frozen Scene (model, checks, load, sources, imus, earth, shapes,
units, presets, flight logs)."""
from imu_emulator.scene.load import from_dict, load_scene
from imu_emulator.scene.model import Expressions, ImuSpec, SampledData, Scene

__all__ = ["Expressions", "ImuSpec", "SampledData", "Scene", "from_dict", "load_scene"]
