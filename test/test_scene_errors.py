"""Each class of bad scene file gives its own clear error.

One case per class: the file is written to a temporary path and loaded with ``load_scene``; the
error must name that file and exactly the key path of the fault (or the line and column, for faults
below the level of keys), say what was expected and what was found. The ``vjm run`` command turns
the same errors into exit code 2 with the file and key on stderr.

The documents are small variations of one valid two-chain scene (``BASE``), so that each case
differs from a loadable scene by the one fault under test.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from vjm_ros.core.errors import SceneError
from vjm_ros.scene.limits import FILE_KEY, MAX_LINKS, MAX_NESTING, MAX_SCENE_BYTES, TOP_KEY
from vjm_ros.scene.loader import load_scene

BASE = """\
name: base
units: {angle: degrees}
chains:
  - name: left
    links:
      - {name: crank, length: 0.2, mass: 1.0, inertia: 0.01,
         joint: {name: crank_joint, type: revolute, angle: 60.0}}
      - {name: coupler, length: 0.8, mass: 1.0, inertia: 0.05,
         joint: {name: coupler_joint, type: revolute, angle: 0.0}}
  - name: right
    origin: [0.6, 0.0]
    links:
      - {name: rocker, length: 0.7, mass: 1.0, inertia: 0.04,
         joint: {name: rocker_joint, type: revolute, angle: 90.0}}
closures:
  - name: pin
    type: hinge
    point: {link: coupler, at: tip}
    target: {link: rocker, at: tip}
actuators:
  - {joint: crank_joint, limit: 10.0}
closure_method: {method: penalty, kp: 1.0e5, kv: 100.0}
assemble:
  fixed: [crank_joint]
defaults: {integrator: rk4, rate: 1000, substeps: 1, duration: 1.0}
"""


def edit(old: str, new: str, text: str = BASE) -> str:
    """``text`` with ``old`` (which must occur exactly once) replaced by ``new``."""
    assert text.count(old) == 1, old
    return text.replace(old, new)


HINGE = "    type: hinge\n    point: {link: coupler, at: tip}\n    target: {link: rocker, at: tip}"
LINK = "      - {{length: 0.1, joint: {{type: revolute, angle: {a}}}}}\n"
LAUGHS = "name: [&l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol], " + ", ".join(
    f"&l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, 10)
) + "]\n"  # 9 ** 10 leaves, shared: small in memory, astronomically long if printed

# 60 mappings each merge one 200-key anchor: 12 000 merged entries, over MAX_MERGED_ENTRIES, refused
# at the '<<' that crosses the limit (the 51st mapping, line 54) by the loader's own merge code,
# the same under every PyYAML 6.x.
MERGE_FLOOD = (
    "name: x\n_base: &b {" + ", ".join(f"k{i}: {i}" for i in range(200)) + "}\n_flood:\n"
    + "".join(f"  - {{<<: *b, own{i}: 1}}\n" for i in range(60))
)

# (class, file contents, key path, words of "expected", words of "found")
CASES = [
    ("not_utf8", BASE.encode().replace(b"base", b"b\xe9se"), "line 1, column 8", "UTF-8 text",
     "0xe9"),
    ("yaml_syntax", edit("  fixed: [crank_joint]", "  fixed: [crank_joint"), "line 25, column 9",
     "valid YAML", "expected ',' or ']'"),
    ("tab_indentation", edit("  - name: right", "\t- name: right"), "line 10, column 1",
     "valid YAML", "found character"),
    ("control_character", edit("name: base", "name: ba\x07se"), "line 1, column 9",
     "printable characters", "U+0007"),
    ("duplicate_key", edit("mass: 1.0, inertia: 0.01", "mass: 1.0, mass: 2.0, inertia: 0.01"),
     "line 6, column 47", "each key once", "'mass' a second time"),
    ("malformed_scalar", edit("name: base", "name: 2024-02-30"), "line 1, column 7",
     "a valid !!timestamp value", "2024-02-30"),
    ("too_deep", edit("defaults:", "description: " + "[" * 40 + "]" * 40 + "\ndefaults:"),
     f"line 25, column {MAX_NESTING + 13}", f"at most {MAX_NESTING} levels", "deeper nesting"),
    ("merge_flood", MERGE_FLOOD, "line 54, column 6", "merge keys ('<<')", "entries"),
    ("not_a_mapping", "- name: base\n- chains: []\n", TOP_KEY, "a mapping", "'name'"),
    ("empty_file", "", TOP_KEY, "a mapping", "None"),
    ("unknown_key", edit("defaults:", "colour: red\ndefaults:"), "colour", "one of the keys",
     "colour"),
    ("missing_key", edit("name: base\n", ""), "name", "a required key", "missing"),
    ("missing_nested_key",
     edit("      - {name: rocker, length: 0.7, mass: 1.0, inertia: 0.04,\n"
          "         joint: {name: rocker_joint, type: revolute, angle: 90.0}}",
          "      - {name: rocker, length: 0.7, mass: 1.0, inertia: 0.04}"),
     "chains[1].links[0].joint", "a required key", "missing"),
    ("wrong_type", edit("mass: 1.0, inertia: 0.05", "mass: heavy, inertia: 0.05"),
     "chains[0].links[1].mass", "a number", "'heavy'"),
    ("negative_mass", edit("mass: 1.0, inertia: 0.04", "mass: -1.0, inertia: 0.04"),
     "chains[1].links[0].mass", "a number >= 0", "-1.0"),
    ("negative_length", edit("length: 0.8", "length: -0.8"), "chains[0].links[1].length",
     "a number >= 0", "-0.8"),
    ("zero_rate", edit("rate: 1000", "rate: 0"), "defaults.rate", "a number > 0", "0"),
    ("nan", edit("inertia: 0.01", "inertia: .nan"), "chains[0].links[0].inertia",
     "a finite number", "nan"),
    ("huge_number", edit("length: 0.2", "length: 1" + "0" * 400), "chains[0].links[0].length",
     "magnitude at most 1e+06", "10000"),
    ("unknown_joint_type", edit("type: revolute, angle: 90.0", "type: spherical, angle: 90.0"),
     "chains[1].links[0].joint.type", "one of ['revolute', 'prismatic']", "'spherical'"),
    ("unknown_closure_type", edit("type: hinge", "type: weld"), "closures[0].type",
     "one of ['hinge', 'slider', 'angle']", "'weld'"),
    ("closure_names_missing_link", edit("{link: rocker, at: tip}", "{link: slider, at: tip}"),
     "closures[0].target.link", "a link of the scene (crank, coupler, rocker)", "'slider'"),
    ("closure_names_missing_point", edit("{link: coupler, at: tip}", "{link: coupler, at: end}"),
     "closures[0].point.at", "'tip', 'origin', 'com' or [s, w]", "'end'"),
    ("closure_point_on_ground", edit("point: {link: coupler, at: tip}", "point: {ground: [0, 0]}"),
     "closures[0].point", "a point on a link", "'ground'"),
    ("actuator_names_missing_joint", edit("{joint: crank_joint, limit", "{joint: knee, limit"),
     "actuators[0].joint", "a joint of the scene (crank_joint, coupler_joint, rocker_joint)",
     "'knee'"),
    ("assemble_names_missing_joint", edit("fixed: [crank_joint]", "fixed: [crank_joint, hip]"),
     "assemble.fixed[1]", "a joint of the scene", "'hip'"),
    ("duplicate_link_name", edit("{name: rocker, length", "{name: crank, length"),
     "chains[1].links[0].name", "a link name used once", "'crank'"),
    ("duplicate_chain_name", edit("name: right", "name: left"), "chains[1].name",
     "a chain name used once", "'left'"),
    ("duplicate_joint_name", edit("name: rocker_joint", "name: crank_joint"),
     "chains[1].links[0].joint.name", "a joint name used once", "'crank_joint'"),
    ("duplicate_actuator",
     edit("  - {joint: crank_joint, limit: 10.0}",
          "  - {joint: crank_joint, limit: 10.0}\n  - {joint: crank_joint}"),
     "actuators[1].joint", "a joint actuated once", "'crank_joint'"),
    ("bad_name", edit("name: base", "name: my scene"), "name", "a name of letters, digits",
     "'my scene'"),
    ("bad_vector", edit("origin: [0.6, 0.0]", "origin: [0.6]"), "chains[1].origin",
     "a list of two numbers [x, y]", "[0.6]"),
    ("zero_direction",
     edit(HINGE, "    type: slider\n    point: {link: coupler, at: tip}\n"
                 "    line: {ground: [0, 0], direction: [0, 0]}"),
     "closures[0].line.direction", "a non-zero vector", "[0, 0]"),
    ("gains_in_closure", edit("    type: hinge\n", "    type: hinge\n    gains: {kp: 1}\n"),
     "closures[0].gains", "gains under the top-level 'closure_method'", "{'kp': 1}"),
    ("angle_target_both",
     edit(HINGE, "    type: angle\n    link: coupler\n    target: {ground: true, link: rocker}"),
     "closures[0].target", "either 'ground: true' or 'link: NAME'", "'ground'"),
    ("effort_beyond_limit", edit("limit: 10.0}", "limit: 10.0, effort: 12.0}"),
     "actuators[0].effort", "within the limit +-10", "12.0"),
    ("unknown_integrator", edit("integrator: rk4", "integrator: verlet"), "defaults.integrator",
     "one of ['explicit_euler'", "'verlet'"),
    ("bad_substeps", edit("substeps: 1", "substeps: 2.5"), "defaults.substeps",
     "a whole number from 1 to 10000", "2.5"),
    ("unknown_closure_method", edit("method: penalty", "method: magic"), "closure_method.method",
     "one of ['penalty', 'exact']", "'magic'"),
    ("gains_both_ways", edit("kv: 100.0}", "kv: 100.0, omega_n: 50.0}"), "closure_method",
     "either kp/kv or omega_n/zeta", "'omega_n'"),
    ("damping_without_stiffness", edit("kp: 1.0e5, kv", "kv"), "closure_method.kv",
     "'kv' together with 'kp'", "100.0"),
    ("unknown_angle_unit", edit("{angle: degrees}", "{angle: grads}"), "units.angle",
     "'degrees' or 'radians'", "'grads'"),
    ("too_many_links",
     "name: long\nchains:\n  - links:\n"
     + "".join(LINK.format(a=0) for _ in range(MAX_LINKS + 1)),
     "chains[0].links", f"a list of at most {MAX_LINKS} entries", f"{MAX_LINKS + 1} entries"),
    ("singular_mass_matrix", edit("mass: 1.0, inertia: 0.04", "mass: 0.0, inertia: 0.0"),
     "chains[1].links[0]", "some mass or inertia moved by joint 'rocker_joint'",
     "smallest eigenvalue"),
    ("closures_do_not_hold", edit("assemble:\n  fixed: [crank_joint]\n", ""), "closures[0]",
     "closures that hold at t = 0 within 1e-06 (or an 'assemble' section)", "residual"),
    ("cannot_assemble", edit("origin: [0.6, 0.0]", "origin: [5.0, 0.0]"), "closures[0]",
     "geometry that assembly can close", "at 'pin' after assembly"),
    ("billion_laughs", LAUGHS + "chains: []\n", "name", "a non-empty string", "[['lol', 'lol'"),
    ("too_large", "name: big\ndescription: '" + "x" * MAX_SCENE_BYTES + "'\n", FILE_KEY,
     f"a file of at most {MAX_SCENE_BYTES} bytes", "more than"),
]


def test_base_scene_loads(tmp_path):
    """The unmodified document is a valid scene, so each case below isolates its one fault."""
    path = tmp_path / "base.yaml"
    path.write_text(BASE)
    scene = load_scene(path)
    assert scene.model.n == 3 and scene.assembly_residual <= 1e-10


@pytest.mark.parametrize(
    "contents, key, expected, found", [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_error_names_file_key_expected_found(tmp_path, contents, key, expected, found):
    path = tmp_path / "bad.yaml"
    if isinstance(contents, bytes):
        path.write_bytes(contents)
    else:
        path.write_text(contents, encoding="utf-8")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    exc = info.value
    assert exc.source == str(path)
    assert exc.key == key
    assert expected in exc.expected
    assert found in repr(exc.found)
    message = str(exc)
    assert message.startswith(f"{path}: {key}: expected {exc.expected}, found ")
    assert len(message) < 1000


def merge_bomb(levels: int) -> str:
    """Each level merges the previous one twice: ``2 ** levels`` entries if copied naively."""
    return "name: x\n_m0: &m0 {a: 1, b: 2}\n" + "".join(
        f"_m{i}: &m{i} {{<<: [*m{i - 1}, *m{i - 1}], k{i}: 1}}\n" for i in range(1, levels + 1)
    )


def test_merge_bomb_costs_little_and_names_the_file(tmp_path):
    """Merge keys that would copy 2**40 entries load in linear memory, and the error names the file.

    A key arrives once however many merged mappings carry it, so level i holds i + 2 entries and
    the whole document a few hundred; the scene builder then refuses the unknown key ``_m0``.
    Budget: 16 MB of Python allocations at the peak (tracemalloc, deterministic for a given
    interpreter); the document itself is 2 kB, and a naive expansion would need terabytes.
    """
    import tracemalloc

    path = tmp_path / "bomb.yaml"
    path.write_text(merge_bomb(40))
    tracemalloc.start()
    try:
        with pytest.raises(SceneError) as info:
            load_scene(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, f"peak {peak / 2**20:.1f} MB"
    assert info.value.source == str(path)
    assert info.value.key == "_m0" and "one of the keys" in info.value.expected


def test_merge_keys_follow_the_yaml_merge_rules(tmp_path):
    """Own keys win over merged ones, the first merged mapping wins over later ones, and a scene
    written with merge keys loads exactly as the same scene written out in full."""
    link = "{name: %s, length: %s, mass: 1.0, inertia: %s, joint: {name: %s, type: revolute}}"
    written_out = edit(
        "      - {name: rocker, length: 0.7, mass: 1.0, inertia: 0.04,\n"
        "         joint: {name: rocker_joint, type: revolute, angle: 90.0}}",
        "      - {name: rocker, length: 0.7, mass: 1.0, inertia: 0.04,\n"
        "         joint: {name: rocker_joint, type: revolute, angle: 90.0}}\n"
        "      - " + link % ("extra", "0.3", "0.02", "extra_joint"),
    )
    merged = edit(
        "      - {name: rocker, length: 0.7, mass: 1.0, inertia: 0.04,\n"
        "         joint: {name: rocker_joint, type: revolute, angle: 90.0}}",
        "      - &rocker {name: rocker, length: 0.7, mass: 1.0, inertia: 0.04,\n"
        "         joint: {name: rocker_joint, type: revolute, angle: 90.0}}\n"
        "      - <<: [{inertia: 0.02, length: 0.3}, *rocker, {length: 9.0}]\n"
        "        name: extra\n"
        "        joint: {name: extra_joint, type: revolute}",
    )
    assert "extra" in written_out  # the extra link hangs off the rocker's tip, free
    a_path, b_path = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a_path.write_text(written_out)
    b_path.write_text(merged)
    a, b = load_scene(a_path), load_scene(b_path)
    assert (a.model.links, a.model.joints) == (b.model.links, b.model.joints)


def test_class_names_unique():
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize(
    "make, expected, found",
    [
        (lambda tmp: tmp / "missing.yaml", "a built-in scene name", "no such scene or file"),
        (lambda tmp: tmp, "a regular file", "a directory or device"),
        (lambda tmp: tmp / ("x" * 5000), "a readable file", "File name too long"),
    ],
    ids=["no_such_file", "directory", "name_too_long"],
)
def test_file_errors(tmp_path, make, expected, found):
    """Faults of the file itself carry the key path FILE_KEY."""
    path = make(tmp_path)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert info.value.key == FILE_KEY and info.value.source == str(path)
    assert expected in info.value.expected and found in repr(info.value.found)


def test_newlines_and_bom_read_like_text_files(tmp_path):
    """CR LF line ends and a UTF-8 byte-order mark load the same scene as plain LF text."""
    plain, crlf = tmp_path / "lf.yaml", tmp_path / "crlf.yaml"
    plain.write_text(BASE)
    crlf.write_bytes(b"\xef\xbb\xbf" + BASE.replace("\n", "\r\n").encode())
    a, b = load_scene(plain), load_scene(crlf)
    assert a.model.joints == b.model.joints and a.text == b.text.lstrip("\ufeff")


@pytest.mark.parametrize("case", ["wrong_type", "closures_do_not_hold", "not_utf8"])
def test_cli_exits_2_naming_file_and_key(tmp_path, case):
    """``vjm run bad.yaml`` exits 2 and prints the file and the key path on stderr."""
    _, contents, key, expected, _ = next(c for c in CASES if c[0] == case)
    path = tmp_path / "bad.yaml"
    if isinstance(contents, bytes):
        path.write_bytes(contents)
    else:
        path.write_text(contents, encoding="utf-8")
    out = subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", "run", str(path), "--duration", "0.01"],
        capture_output=True,
        text=True,
        timeout=120,
        env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"),
    )
    assert out.returncode == 2, out.stderr
    assert f"{path}: {key}: expected {expected}" in out.stderr
    assert out.stdout == ""
