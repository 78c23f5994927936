"""The notebook-style tour (examples/notebook_tour.py) run as a user would: scene → run → DataFrame → Figure →
bag → read_bag → the same DataFrame (issue 21)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
TOUR = ROOT / "examples" / "notebook_tour.py"


def test_tour_runs_as_a_script(tmp_path):
    """In a new process, as `python examples/notebook_tour.py OUT`: exit 0, the figure and the bag written, and the
    DataFrame read back from the bag equal to the run's."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    r = subprocess.run([sys.executable, str(TOUR), str(tmp_path / "out")], capture_output=True, text=True,
                       timeout=600, cwd=tmp_path, env=env)
    print("\n" + r.stdout)
    assert r.returncode == 0, r.stderr
    assert "the same DataFrame: True" in r.stdout
    png = (tmp_path / "out" / "tour_run.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "out" / "tour_bag" / "metadata.yaml").is_file()


def test_tour_cells_in_process(tmp_path, monkeypatch):
    """The same cells in this process (as a notebook kernel runs them): the objects each cell leaves are what a
    user gets: a DataFrame with units, a Figure, a result read back from the bag equal to the run's, and the
    backend the user had still in force."""
    import runpy

    import matplotlib.figure

    backend = matplotlib.get_backend()
    monkeypatch.setattr(sys, "argv", [str(TOUR), str(tmp_path / "out")])
    g = runpy.run_path(str(TOUR), run_name="__main__")
    assert matplotlib.get_backend() == backend
    df, again, result = g["df"], g["again"], g["result"]
    assert isinstance(df, pd.DataFrame) and df.index.name == "t" and df.attrs["units"]["spin_rate"] == "rad/s"
    assert isinstance(g["fig"], matplotlib.figure.Figure)
    pd.testing.assert_frame_equal(again.to_dataframe(), df)
    assert np.array_equal(again.L, result.L) and np.array_equal(again.t, result.t)
    assert df.index[-1] == pytest.approx(5.0, abs=1e-12)
