"""The code version a result records: a checkout is dirty when its code, configs or models differ from the commit,
not when results recorded into it do (an experiment writes its committed journal with every run)."""

import subprocess

from roshan.runs import provenance


def git(repo, *args):
    subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)


def test_only_changes_to_code_configs_or_models_make_a_checkout_dirty(tmp_path, monkeypatch):
    for path in ("roshan/core.py", "configs/a.yaml", "models/m/README.md", "benchmarks/results/x.journal"):
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text("v1\n")
    git(tmp_path, "init", "-q")
    git(tmp_path, "add", ".")
    git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "c")
    monkeypatch.setattr(provenance, "SOURCE_ROOT", tmp_path.resolve())
    clean = provenance.code_version()
    assert len(clean["commit"]) == 40 and clean["dirty"] is False

    (tmp_path / "benchmarks/results/x.journal").write_text("v1\nanother run\n")  # a result recorded
    (tmp_path / "notes.txt").write_text("untracked\n")
    assert provenance.code_version()["dirty"] is False
    for path in ("configs/a.yaml", "models/m/README.md", "roshan/core.py"):
        (tmp_path / path).write_text("v2\n")
        assert provenance.code_version()["dirty"] is True, path
        git(tmp_path, "checkout", "--", path)
    assert provenance.code_version()["dirty"] is False
