"""Flow fields for saltation: LES snapshot datasets in wall units and their Numba sampler.

``open_dataset(path=None)`` opens a dataset folder (None: the shipped LES-WALE channel).
"""
from ._numba_cache import use_versioned_cache

use_versioned_cache()  # before any kernel is compiled or loaded

from .dataset import DatasetError, FlowDataset, open_dataset, SHIPPED_DATASET
from .analytic import profile_dataset

__all__ = ["open_dataset", "FlowDataset", "DatasetError", "profile_dataset", "SHIPPED_DATASET"]
