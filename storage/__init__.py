"""Results storage: BaseStorage, InMemoryStorage, Hdf5Storage (the only package that imports h5py).

Hdf5Storage is imported lazily so that importing `storage` stays light.
"""

from storage.base import BaseStorage
from storage.memory import InMemoryStorage
from storage.schema import FILE_SCHEMA_VERSION, RunMeta, TrialRecord

__all__ = ["FILE_SCHEMA_VERSION", "BaseStorage", "InMemoryStorage", "RunMeta", "TrialRecord"]
