"""A recording (MCAP) into numpy arrays, and into pandas DataFrames when pandas is installed.

plumeswarm demo                       # records runs/<time>/recording.mcap
python examples/read_recording.py runs/<time>/recording.mcap
"""

import argparse

import numpy as np

from recorder.flight_log import load_flight
from recorder.reader import Recording

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("recording", help="an .mcap file written by plumeswarm (or its first segment)")
args = parser.parse_args()

flight = load_flight(Recording.open(args.recording), progress=False)
for vid in flight.vehicles:
    track = flight.tracks[vid].columns  # name -> array, one row per recorded tick
    readings = flight.readings[vid].columns  # unavailable readings are NaN
    xyz = np.column_stack([track["x_m"], track["y_m"], track["z_m"]])
    path_m = float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum())
    reported = readings["reported_g_m3"]
    print(
        f"{vid}: {len(track['sim_time_s'])} states over {track['sim_time_s'][-1]:.1f} s, "
        f"flew {path_m:.1f} m, max altitude {track['z_m'].max():.1f} m, "
        f"{len(reported)} readings, peak {np.nanmax(reported, initial=0.0):.4f} g/m3"
    )

try:
    import pandas as pd
except ImportError:
    pd = None
if pd is not None:
    frames = [pd.DataFrame(flight.tracks[v].columns).assign(vehicle=v) for v in flight.vehicles]
    tracks = pd.concat(frames, ignore_index=True)
    print(f"pandas: {len(tracks)} rows, columns {', '.join(tracks.columns)}")
