"""A notebook's worth of gyro_sim, as a plain script: scene → run → DataFrame → Figure → bag → read_bag.

Run it as it is (``python examples/notebook_tour.py [OUT_DIR]``, default ``runs/tour``) or paste its cells into a
notebook; ``test/test_notebook.py`` runs it, so it cannot rot. Needs the extra ``data`` (pandas, xarray):
``pip install 'gyro_sim[data]'``. Every quantity is SI; frames as in the README (L case frame, Ω body frame).
"""
import sys
from pathlib import Path

import gyro_sim
from gyro_sim.io.plotting import plot_run
from gyro_sim.io.recording import record_result

out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/tour")
out.mkdir(parents=True, exist_ok=True)

# %% a scene: the default spin-up of a thin shell by one rotating field (YAML in config/, SI units)
scene = gyro_sim.load_scene("spinup_thin_shell")

# %% a run in-process, 5 s of the 60 s the scene states; its repr is a short summary
result = gyro_sim.run(scene, duration=5.0)
print(repr(result))

# %% the time series as a pandas DataFrame: index t (s), units and frames in df.attrs
df = result.to_dataframe()
print(df.filter(regex="^(spin_rate|theta|current_)").tail(3))
print("units:", {k: df.attrs["units"][k] for k in ("spin_rate", "theta", "L_z")})

# %% ... and as an xarray Dataset (dims time, component, stator, ...)
ds = result.to_xarray()
print(ds["L"].sel(component="z").isel(time=-1).item(), ds["L"].attrs["units"], ds["L"].attrs["frame"])

# %% a matplotlib Figure to restyle or save (no backend is switched: works inline in a notebook)
fig = plot_run(result)
fig.axes[0].set_title("spin-up of a thin shell, first 5 s")
fig.savefig(out / "tour_run.png", dpi=90)

# %% the run as a rosbag2 MCAP bag (Foxglove, ros2 bag, rosbags read it), and back as the same result
bag = record_result(result, out / "tour_bag")
again = gyro_sim.read_bag(bag)
same = again.to_dataframe().equals(df)
print(f"bag {bag}: read back, the same DataFrame: {same}")
