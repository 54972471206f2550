"""Weight files: ICT/ARKit CSV, Live Link Face CSV, JSON layouts, errors, range checks, writing."""
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from data_synth.facs import ARKIT_NAMES, FACS_INDEX, FACS_NAMES
from retarget.errors import RetargetError
from retarget.weights_io import WeightRangeWarning, read_weights, write_weights_csv

BAD = Path(__file__).parent / "bad_inputs"
I = FACS_INDEX


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_ict_csv_case_insensitive_with_frame_column(tmp_path):
    p = write(tmp_path, "w.csv", "Frame,JAWOPEN,eyeblink_l,mouthSmile_R\n0,0.5,0.25,0\n1,0.75,0,1\n")
    w, fps = read_weights(p)
    assert w.shape == (2, 53) and w.dtype == np.float32 and fps is None
    assert w[0, I["jawOpen"]] == 0.5 and w[0, I["eyeBlink_L"]] == 0.25 and w[1, I["mouthSmile_R"]] == 1
    others = np.delete(w, [I["jawOpen"], I["eyeBlink_L"], I["mouthSmile_R"]], axis=1)
    assert not others.any()  # names not in the file are 0


def test_arkit_csv_mapping(tmp_path):
    p = write(tmp_path, "a.csv", "browInnerUp,cheekPuff,tongueOut,eyeBlinkLeft,mouthSmileRight\n0.4,0.6,0.9,0.1,0.2\n")
    w = read_weights(p).weights[0]
    assert w[I["browInnerUp_L"]] == w[I["browInnerUp_R"]] == np.float32(0.4)
    assert w[I["cheekPuff_L"]] == w[I["cheekPuff_R"]] == np.float32(0.6)
    assert w[I["eyeBlink_L"]] == np.float32(0.1) and w[I["mouthSmile_R"]] == np.float32(0.2)
    assert np.isclose(w.sum(), 0.4 * 2 + 0.6 * 2 + 0.1 + 0.2)  # tongueOut dropped


def llf_csv(n_frames, rate=60, start_frame=55):
    """A Live Link Face style CSV: 60 fps timecodes, all 52 ARKit names in PascalCase, rotations."""
    rng = np.random.default_rng(1)
    values = rng.uniform(0, 1, (n_frames, len(ARKIT_NAMES)))
    header = ["Timecode", "BlendShapeCount"] + [n[0].upper() + n[1:] for n in ARKIT_NAMES] + \
             ["HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
              "RightEyeYaw", "RightEyePitch", "RightEyeRoll"]
    lines = [",".join(header)]
    for t in range(n_frames):
        f = start_frame + t
        s, ff = divmod(f, rate)
        code = f"12:34:{s:02d}:{ff:02d}.{t % 1000:03d}"
        lines.append(",".join([code, "61"] + [f"{v:.6f}" for v in values[t]] + ["0.3"] * 9))
    return "\n".join(lines) + "\n", values


def test_live_link_face_csv(tmp_path):
    text, values = llf_csv(150)
    w, fps = read_weights(write(tmp_path, "MySlate_3_iPhone.csv", text))
    assert w.shape == (150, 53)
    assert fps == pytest.approx(60.0)
    col = {n: j for j, n in enumerate(ARKIT_NAMES)}
    assert np.allclose(w[:, I["eyeBlink_L"]], values[:, col["eyeBlinkLeft"]], atol=1e-6)
    assert np.allclose(w[:, I["cheekPuff_R"]], values[:, col["cheekPuff"]], atol=1e-6)
    assert np.allclose(w[:, I["jawOpen"]], values[:, col["jawOpen"]], atol=1e-6)
    # under two whole seconds of timecode the rate cannot be told
    assert read_weights(write(tmp_path, "short.csv", llf_csv(20)[0])).fps is None


def test_json_layouts(tmp_path):
    one = read_weights(write(tmp_path, "one.json", json.dumps({"jawOpen": 0.5, "EyeBlinkLeft": 1})))
    assert one.weights.shape == (1, 53) and one.weights[0, I["jawOpen"]] == 0.5 and one.weights[0, I["eyeBlink_L"]] == 1
    many = read_weights(write(tmp_path, "many.json", json.dumps([{"jawOpen": 0.1}, {"mouthPucker": 0.2}])))
    assert many.weights.shape == (2, 53) and many.weights[1, I["mouthPucker"]] == np.float32(0.2)
    assert many.weights[1, I["jawOpen"]] == 0
    table = {"names": ["jawOpen", "browInnerUp"], "frames": [[0.1, 0.2], [0.3, 0.4], [0, 0]], "fps": 24}
    t = read_weights(write(tmp_path, "table.json", json.dumps(table)))
    assert t.fps == 24 and t.weights.shape == (3, 53)
    assert t.weights[1, I["browInnerUp_R"]] == np.float32(0.4)
    dicts = read_weights(write(tmp_path, "dicts.json", json.dumps({"fps": 30, "frames": [{"jawOpen": 1}]})))
    assert dicts.fps == 30 and dicts.weights[0, I["jawOpen"]] == 1


def test_out_of_range_warns_or_clamps(tmp_path):
    p = write(tmp_path, "r.csv", "jawOpen,eyeBlink_L,eyeBlink_R\n1.5,-0.25,1.0000001\n0.5,0.5,0\n")
    with pytest.warns(WeightRangeWarning, match=r"r\.csv: 2 weights outside \[0, 1\]"):
        w = read_weights(p).weights
    assert w[0, I["jawOpen"]] == 1.5 and w[0, I["eyeBlink_L"]] == -0.25
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        c = read_weights(p, clamp=True).weights
    assert c[0, I["jawOpen"]] == 1 and c[0, I["eyeBlink_L"]] == 0 and c[1, I["jawOpen"]] == 0.5


@pytest.mark.parametrize("names", ["ict", "arkit"])
def test_write_read_round_trip(tmp_path, names):
    w = np.random.default_rng(2).uniform(0, 1, (4, 53)).astype(np.float32)
    out = tmp_path / "out" / f"w_{names}.csv"
    write_weights_csv(out, w, names=names, fps=25)
    back, fps = read_weights(out)
    assert fps == pytest.approx(25)
    header = out.read_text().splitlines()[0].split(",")
    assert header[:2] == ["frame", "time"]
    if names == "ict":
        assert header[2:] == list(FACS_NAMES)
        assert np.allclose(back, w, atol=1e-5)
    else:
        assert header[2:] == list(ARKIT_NAMES)
        for pair in ("browInnerUp", "cheekPuff"):  # one ARKit channel = mean of the ICT halves
            mean = 0.5 * (w[:, I[pair + "_L"]] + w[:, I[pair + "_R"]])
            assert np.allclose(back[:, I[pair + "_L"]], mean, atol=1e-5)
            assert np.allclose(back[:, I[pair + "_R"]], mean, atol=1e-5)
        rest = [i for n, i in I.items() if not n.startswith(("browInnerUp", "cheekPuff"))]
        assert np.allclose(back[:, rest], w[:, rest], atol=1e-5)
    assert [p.name for p in out.parent.iterdir()] == [out.name]


WEIGHT_CASES = {
    "empty.csv": "is empty",
    "header_only.csv": "no frames",
    "no_header.csv": "first row must name",
    "missing_cell.csv": "row 3, column 'eyeBlink_L': missing value",
    "short_row.csv": "row 3, column 'eyeBlink_L': missing value",
    "long_row.csv": "row 2 has 3 cells",
    "text_in_number.csv": "row 3, column 'jawOpen': 'abc' is not a number",
    "nan_weight.csv": "not a finite number",
    "unknown_names.csv": "unknown blendshape names: smileBig, frownish",
    "duplicate_names.csv": "both set browInnerUp_L",
    "llf_text.csv": "row 3, column 'EyeBlinkLeft': 'x' is not a number",
    "unknown_format.txt": "unknown weight format .txt",
    "empty.json": "is empty",
    "bad_syntax.json": "not valid JSON",
    "wrong_shape.json": "wrong JSON layout",
    "wrong_shape_number.json": "wrong JSON layout",
    "names_mismatch.json": "frame 1 has 1 values but there are 2 names",
    "unknown_names.json": "unknown blendshape names: tongueTwist",
    "text_in_number.json": "frame 1, column 'jawOpen': 'half' is not a number",
    "null_value.json": "missing value",
    "missing.csv": "no such file",
    "seq_faces": "is a folder",
    "only_commas.csv": "row 3 holds only commas",
    "nul_bytes.csv": "holds binary data",
    "wide.csv": "unknown blendshape names: extra0, extra1, extra2, extra3, extra4, extra5, extra6, "
                "extra7, extra8, extra9 and 9,990 more (expected",
    "huge_integer.json": "not usable JSON",
    "big_integer.json": "not a finite number",
    "huge_number.json": "far outside [0, 1]",
    "deep.json": "nested too deeply",
    "fps_zero.json": "frame rate must be a finite number above 0",
    "fps_negative.json": "frame rate must be a finite number above 0",
}


@pytest.mark.parametrize("name,fragment", sorted(WEIGHT_CASES.items()))
def test_bad_weight_inputs(tmp_path, name, fragment):
    """Each bad file: RetargetError naming it (and row/column), input untouched, no output left."""
    src = BAD / name
    before = src.read_bytes() if src.is_file() else None
    out = tmp_path / "weights.csv"
    with pytest.raises(RetargetError) as err:
        write_weights_csv(out, read_weights(src).weights)
    msg = str(err.value)
    assert msg.startswith(str(src) + ":") and fragment in msg and "\n" not in msg
    assert (src.read_bytes() if src.is_file() else None) == before
    assert list(tmp_path.iterdir()) == []


def test_write_refuses_bad_destination(tmp_path):
    blocker = write(tmp_path, "file", "x")
    with pytest.raises(RetargetError, match="cannot write to folder"):
        write_weights_csv(blocker / "w.csv", np.zeros((1, 53)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"] and blocker.read_text() == "x"
