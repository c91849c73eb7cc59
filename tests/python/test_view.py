"""trellis_mech.view: the same page as `trellis view` (docs/viewer.md), bad input as ValueError with
no file left behind, stand-in meshes as warnings. The page in a browser: tests/viewer/."""
import base64
import html
import json
import os
import re
import warnings

import numpy as np
import pytest

import trellis_mech as tm

from conftest import SCENES, SOURCE_DIR, TRAJECTORIES

VIEWER_DATA = SOURCE_DIR / "tests" / "data" / "viewer"


def page_data(path):
    text = path.read_text()
    match = re.search(r'<script type="application/json" id="trellis-data">(.*?)</script>', text, re.S)
    assert match, "no data block"
    return json.loads(match.group(1))


def test_view_holds_the_library_kinematics_at_the_knots(tmp_path):
    scene = tm.load_scene(str(SCENES / "pendulum.json"))
    swing = tm.Trajectory.read_csv(str(TRAJECTORIES / "pendulum_swing.csv"))
    out = tmp_path / "pendulum.html"
    page = tm.view(scene, swing, path=str(out), names=["swing"])
    assert page.path == str(out) and os.fspath(page) == str(out) and str(page) == str(out)
    assert page.html == out.read_text() and page.samples > swing.times.size and page.warnings == []
    assert tm.view(scene, swing, str(tmp_path / "second.html")).path == str(tmp_path / "second.html")
    data = page_data(out)
    (shown,) = data["trajectories"]
    assert shown["name"] == "swing" and not shown["ghost"]
    times = np.frombuffer(base64.b64decode(shown["t"]), dtype="<f8")
    poses = np.frombuffer(base64.b64decode(shown["poses"]), dtype="<f8").reshape(len(times), -1, 7)
    model = scene.model
    d = tm.Data(model)
    bob = model.frame_index("bob")
    for k in (1, 40):
        t = swing.times[k]
        (s,) = np.nonzero(times == t)[0]
        q = swing.states[k, : model.nq]
        tm.compute_kinematics(model, d, q, np.zeros(model.nq))
        # The body's joint frame (pivot) rotated onto the bob's placement (0, -1, 0).
        w, x, y, z = poses[s, 0, 3:]
        rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                             [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                             [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        placed = poses[s, 0, :3] + rotation @ np.array([0.0, -1.0, 0.0])
        expected = np.asarray(d.frame_poses[bob])[:3, 3]
        assert np.max(np.abs(placed - expected)) < 1e-14
        assert abs(expected[0]) > 0.1  # the bob is away from the hanging position: the check can fail


def test_view_of_a_urdf_file_keeps_its_visuals_and_warns_for_a_stand_in(tmp_path):
    out = tmp_path / "arm.html"
    tm.view(VIEWER_DATA / "arm.urdf", out)  # the path as the last positional argument (os.PathLike)
    with pytest.raises(TypeError, match="no path"):
        tm.view(VIEWER_DATA / "arm.urdf")
    data = page_data(out)
    assert sorted(v["shape"] for v in data["visuals"]) == ["box", "cylinder", "mesh", "sphere"]
    with pytest.warns(UserWarning, match="not supported"):
        tm.view(str(VIEWER_DATA / "dae_mesh.urdf"), path=str(tmp_path / "dae.html"))


def test_view_bad_input_is_a_value_error_and_writes_nothing(tmp_path):
    cart_pole = tm.load_scene(str(SCENES / "cart_pole.json"))
    swing = tm.Trajectory.read_csv(str(TRAJECTORIES / "pendulum_swing.csv"))
    out = tmp_path / "bad.html"
    with pytest.raises(ValueError, match="trajectory 1"):
        tm.view(cart_pole, swing, path=str(out))
    with pytest.raises(ValueError, match="cylinder length"):
        tm.view(str(VIEWER_DATA / "bad_visual.urdf"), path=str(out))
    with pytest.raises(ValueError, match="q has 3 entries"):
        tm.view(cart_pole, path=str(out), q=np.zeros(3))
    assert not out.exists()


def test_view_shows_inline_in_a_notebook_through_repr_html(tmp_path):
    """Jupyter shows a cell's value by its _repr_html_: the page itself in an iframe's srcdoc."""
    scene = tm.load_scene(str(SCENES / "pendulum.json"))
    page = tm.view(scene, path=tmp_path / "state.html")
    shown = page._repr_html_()
    assert shown.startswith("<iframe ") and shown.endswith("></iframe>")
    srcdoc = re.search(r'srcdoc="([^"]*)"', shown).group(1)
    assert html.unescape(srcdoc) == page.html  # the whole page, escaped for the attribute
    assert "<" not in srcdoc and '"' not in srcdoc
    assert 'height: 300px' in page._repr_html_(height=300)
    assert "ViewPage" in repr(page)


def test_view_draws_constraint_forces_unless_asked_not_to(tmp_path):
    scene = tm.load_scene(str(SCENES / "paper_pendulum.json"))
    swing = tm.Trajectory.read_csv(str(TRAJECTORIES / "paper_pendulum_swing.csv"))
    tm.view(scene, swing, path=tmp_path / "forces.html")
    data = page_data(tmp_path / "forces.html")
    assert len(data["arrows"]) == 1 and "forces" in data["trajectories"][0]
    tm.view(scene, swing, path=tmp_path / "none.html", forces=False)
    data = page_data(tmp_path / "none.html")
    assert "arrows" not in data and "forces" not in data["trajectories"][0]
