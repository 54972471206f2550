"""Every documented Python example runs as written: the README's ```python blocks (in order, in one
namespace, as a reader pastes them into one session), the indented examples of the package
docstrings and the import blocks of docs/ARCHITECTURE.md, each in a temporary folder holding small versions of the files they name (target.obj,
src_frame.obj, frame.obj, actor_neutral.obj, cap/0000.obj ...: procedural heads of a few hundred vertices)."""
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

import data_synth
import data_synth.tessellate  # noqa: F401  (a submodule named like an export, imported first)
import retarget
import retarget.api
from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.sampling import smooth_sequence
from data_synth.tessellate import tessellate
from retarget.io import save_mesh

ROOT = Path(__file__).resolve().parents[1]
N_CAPTURE = 100   # the README reads cap/0000.obj .. cap/0099.obj


def python_blocks(path: Path) -> list[str]:
    """The ```python blocks of a markdown file."""
    text = path.read_text(encoding="utf-8")
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)


def docstring_examples(doc: str) -> list[str]:
    """The indented code blocks of a docstring (lines indented 4+ spaces after a blank line)."""
    blocks, current = [], []
    for line in doc.splitlines() + [""]:
        if line.startswith("    "):
            current.append(line)
        elif current:
            blocks.append(textwrap.dedent("\n".join(current)))
            current = []
    return blocks


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    """The files the examples name, on small procedural heads (another identity and another
    tessellation for the source than for the target)."""
    folder = tmp_path_factory.mktemp("docs")
    target = build_rig(sample_identity(0, split="test"), tessellate(500, kind="regular", seed=0))
    source = build_rig(sample_identity(1, split="test"), tessellate(400, kind="jittered", seed=1))
    save_mesh(folder / "target.obj", target.neutral, target.faces)
    take = source.evaluate(smooth_sequence(np.random.default_rng(0), N_CAPTURE))
    save_mesh(folder / "src_frame.obj", take[10], source.faces)
    save_mesh(folder / "frame.obj", take[20], source.faces)
    save_mesh(folder / "actor_neutral.obj", source.neutral, source.faces)
    for i, frame in enumerate(take):
        save_mesh(folder / "cap" / f"{i:04d}.obj", frame, source.faces)
    return folder


def run(code: str, where: str, namespace: dict) -> None:
    exec(compile(code, where, "exec"), namespace)


def test_readme_python_blocks_run_as_written(files, monkeypatch):
    blocks = python_blocks(ROOT / "README.md")
    assert len(blocks) >= 3   # the API, trimesh inputs, procedural rigs
    monkeypatch.chdir(files)
    namespace: dict = {}
    for i, code in enumerate(blocks):
        run(code, f"README.md python block {i + 1}", namespace)
    # the API block really ran: its outputs have the documented shapes
    n_target = namespace["tgt"].n_vertices
    assert namespace["seq"].shape == (N_CAPTURE, n_target, 3)
    assert namespace["verts_seq"].shape == (30, n_target, 3) and namespace["w"].shape == (53,)
    assert len(list((files / "out").glob("*.obj"))) == N_CAPTURE
    assert namespace["frame"].shape == namespace["rig"].neutral.shape


def test_architecture_contract_blocks_import():
    """docs/ARCHITECTURE.md's blocks (imports and signatures in comments) name what exists."""
    blocks = python_blocks(ROOT / "docs" / "ARCHITECTURE.md")
    assert blocks
    for i, code in enumerate(blocks):
        run(code, f"docs/ARCHITECTURE.md python block {i + 1}", {})


@pytest.mark.parametrize("module", [data_synth, retarget, retarget.api], ids=lambda m: m.__name__)
def test_docstring_examples_run_as_written(module, files, monkeypatch):
    examples = docstring_examples(module.__doc__)
    assert examples, f"{module.__name__} documents no example"
    monkeypatch.chdir(files)
    for i, code in enumerate(examples):
        run(code, f"{module.__name__} docstring example {i + 1}", {})


def test_docstring_examples_are_found():
    doc = "Title.\n\n    a = 1\n    b = a\n\nText.\n\n    c = 2\n"
    assert docstring_examples(doc) == ["a = 1\nb = a", "c = 2"]


def test_an_export_named_like_its_module_stays_the_export():
    import sys
    import types

    module = sys.modules["data_synth.tessellate"]          # imported at the top
    assert isinstance(data_synth.tessellate, types.FunctionType)
    assert data_synth.tessellate is module.tessellate
    assert data_synth.Tessellation is module.Tessellation
    assert isinstance(data_synth.head, types.ModuleType)             # other submodules as usual
