"""`caustics_jax.runtime.progress`: bars on a terminal only, forced on or off by CAUSTICS_JAX_PROGRESS."""

import io
import sys

import pytest

from caustics_jax.runtime import progress as prog


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _drawn(monkeypatch, stream, env=None):
    if env is None:
        monkeypatch.delenv(prog.ENV, raising=False)
    else:
        monkeypatch.setenv(prog.ENV, env)
    monkeypatch.setattr(sys, "stderr", stream)
    for _ in prog.progress(range(3), desc="work"):
        pass
    return "work" in stream.getvalue()


def test_progress_draws_on_a_terminal_only(monkeypatch):
    assert _drawn(monkeypatch, _Terminal())
    assert not _drawn(monkeypatch, io.StringIO())  # a pipe, a CI log, pytest's capture


@pytest.mark.parametrize("value, terminal, drawn", [("0", True, False), ("off", True, False),
                                                    ("1", False, True), ("yes", False, True)])
def test_progress_environment_variable_forces_bars(monkeypatch, value, terminal, drawn):
    assert _drawn(monkeypatch, _Terminal() if terminal else io.StringIO(), value) is drawn


def test_progress_stays_off_the_standard_output(monkeypatch, capsys):
    monkeypatch.setenv(prog.ENV, "1")
    with prog.progress(total=4, desc="photons") as bar:
        bar.update(4)
    out, err = capsys.readouterr()
    assert out == "" and "photons" in err
