"""``georeg track``: a displacement field per deformed stereo pair, serially or on Dask, and its output files."""

from georeg_app.series.dask import run_series_dask, dask_client
from georeg_app.series.frames import FrameResult, measure_frame, chained_frame, log_frame
from georeg_app.series.outputs import (SUMMARY_FILE, PVD_FILE, REPORT_FILE, frame_file,
                                       track_summary, pvd_text, write_track)
from georeg_app.series.reference import (SeriesReference, load_reference, displacement_solver,
                                         check_frames, series_reference)
from georeg_app.series.track import TrackRun, run_series, run_track

__all__ = ["run_series_dask", "dask_client", "FrameResult", "measure_frame", "chained_frame",
           "log_frame", "SUMMARY_FILE", "PVD_FILE", "REPORT_FILE", "frame_file", "track_summary",
           "pvd_text", "write_track", "SeriesReference", "load_reference", "displacement_solver",
           "check_frames", "series_reference", "TrackRun", "run_series", "run_track"]
