"""Results storage: BaseStorage, InMemoryStorage, Hdf5Storage (the only package that imports h5py).

Hdf5Storage is imported lazily so that importing `storage` stays light.
"""

from spinefarm.storage.base import BaseStorage
from spinefarm.storage.memory import InMemoryStorage
from spinefarm.storage.schema import FILE_SCHEMA_VERSION, RunMeta, TrialRecord

__all__ = ["FILE_SCHEMA_VERSION", "BaseStorage", "InMemoryStorage", "RunMeta", "TrialRecord"]
