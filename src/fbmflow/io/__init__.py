"""Files a run leaves: checkpoints (h5py), per-step run data (h5py, CSV export) and field output."""
from .checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from .fields import FieldWriter
from .rundata import RunData, export_csv

__all__ = ["FieldWriter", "CheckpointError", "load_checkpoint", "save_checkpoint", "RunData", "export_csv"]
