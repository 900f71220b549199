"""Flow fields for saltation: LES snapshot datasets in wall units and their Numba sampler.

``open_dataset(path=None)`` opens a dataset folder (None: the shipped LES-WALE channel).
"""
from ._numba_cache import use_versioned_cache
from ._openmp import use_short_spin

use_versioned_cache()  # before any kernel is compiled or loaded
use_short_spin()  # before the first parallel kernel loads libgomp

from .analytic import profile_dataset  # noqa: E402  (after the cache is set)
from .dataset import SHIPPED_DATASET, DatasetError, FlowDataset, open_dataset  # noqa: E402

__all__ = ["open_dataset", "FlowDataset", "DatasetError", "profile_dataset", "SHIPPED_DATASET"]
