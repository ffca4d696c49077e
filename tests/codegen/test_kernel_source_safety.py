"""No user text reaches generated kernel source (issue 8 item 1): every string field of a scene -- IMU names,
the scene path, param names, expression text, stream table strings, the scene name -- is fed newlines, quotes,
NUL and unicode, and the source `generate_source` prints is tokenized and parsed to show that none of it appears
outside a string literal, in a comment, or as a name, and that the module holds nothing but imports, constant
assignments and function definitions."""
import ast
import dataclasses
import io
import os
import tokenize

import pytest

from imu_emulator import SceneError, scene_from_dict
from imu_emulator.codegen.generate import generate_source
from imu_emulator.runtime.simulation import Simulation

EXPLOIT = 'a\nimport os; os.system("touch PWNED")\nif 1:\n    if 1:'
HOSTILE = [
    EXPLOIT,
    "q'\"\"\"'''\\\\\n# x\r\nPWNED = 1",
    "nul\x00byte\x00PWNED",
    "ünïcødé ✓ \u202e\u2028PWNED\u2029 𝔘",
    "\\\n)]}PWNED({[",
]
PARAM = "ünïpårám"          # a unicode identifier: allowed as a param name, must not become a name in the source


def _scene(hostile: str):
    """Hostile text wherever validation lets it through; the IMU names, which validation now limits to one
    printable line, are put in afterwards, so the generator is checked on its own as well."""
    scene = scene_from_dict({
        "scene": {"rate_hz": 100, "duration_s": 0.05, "name": hostile},
        "params": {PARAM: 1.5, "w": f"2*pi*{PARAM}"},
        # a newline inside parentheses is a valid expression; its text must not reach the source verbatim
        "trajectory": {"x": f"(0.5 *\n {PARAM} * t)", "y": "\tsin(w*t)  ", "z": "0"},
        "attitude": {"yaw": "0.1*t  # PWNED", "roll": "0"},
        "imu": [{"name": "a", "lever_arm_m": [0.1, 0.0, 0.0], "mounting_rpy_deg": [1.0, 2.0, 3.0]},
                {"name": "b"}],
        "effects": {"gravity": True, "lever_arm": True, "mounting": True},
        "stream": [{"imu": hostile, "format": hostile, "to": hostile, hostile: hostile}],
    }, path=hostile)
    return dataclasses.replace(scene, imus=tuple(dataclasses.replace(imu, name=hostile + str(i))
                                                 for i, imu in enumerate(scene.imus)))


def _fragments(hostile: str):
    """Distinctive pieces of the hostile text: any of them in the source means user text got in."""
    pieces = {hostile, PARAM, "PWNED", "ünï", "\x00", "\u202e", "os.system"}
    pieces |= {line.strip() for line in hostile.splitlines() if len(line.strip()) >= 3}
    return pieces


@pytest.mark.parametrize("hostile", HOSTILE, ids=range(len(HOSTILE)))
@pytest.mark.parametrize("truth", [False, True])
def test_no_user_text_in_generated_source(hostile, truth):
    source = generate_source(_scene(hostile), attitude=True, truth=truth)
    tree = ast.parse(source)
    outside_strings = []
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.STRING:
            ast.literal_eval(tok.string)          # a plain literal, nothing evaluated
            continue
        if tok.type == tokenize.NAME:
            assert tok.string.isascii(), tok.string
        outside_strings.append(tok.string)        # names, numbers, operators, comments
    text = " ".join(outside_strings)
    for piece in _fragments(hostile):
        assert piece not in text, f"{piece!r} reached the generated source"
    assert source.isascii(), "non-ASCII text in the generated source"
    for node in tree.body:
        assert isinstance(node, (ast.Import, ast.ImportFrom, ast.Assign, ast.FunctionDef)), ast.dump(node)[:200]
        if isinstance(node, ast.Assign):          # module-level constants: literals only
            ast.literal_eval(node.value)
        if isinstance(node, ast.Import):
            assert all(a.name in ("math", "numba", "numpy") for a in node.names)
        if isinstance(node, ast.ImportFrom):
            assert node.module.startswith("imu_emulator.")


@pytest.mark.parametrize("name", [EXPLOIT, "nul\x00", "tab\tname", "x" * 65])
def test_imu_names_are_one_printable_line(name):
    with pytest.raises(SceneError, match=r"imu\[0\].name: expected a printable name"):
        scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 0.3}, "trajectory": {"x": "t", "y": "0", "z": "0"},
                         "imu": [{"name": name}]})


def test_the_reported_exploit_runs_no_code(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scene = scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 0.3}, "trajectory": {"x": "t", "y": "0", "z": "0"},
                             "imu": [{"name": "a"}]}, path=EXPLOIT)
    scene = dataclasses.replace(scene, imus=(dataclasses.replace(scene.imus[0], name=EXPLOIT),))
    out = Simulation(scene).run()
    assert out.accel.shape == (1, 3, 3)
    assert not os.path.exists(tmp_path / "PWNED")
