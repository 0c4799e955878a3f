"""Keys for the taylor back-end's per-process caches (compiled problems, verified enclosures)."""

from __future__ import annotations

import hashlib
import pickle


def fingerprint(*objects) -> str:
    """A digest of picklable objects; an object that cannot be pickled (a model built in Python with
    a control law implemented by a local function) is identified by its identity in this process,
    so a cache entry keyed by one must keep the object alive."""
    digest = hashlib.sha1()
    for obj in objects:
        try:
            digest.update(pickle.dumps(obj))
        except (TypeError, AttributeError, pickle.PicklingError):
            digest.update(f"object-{id(obj)}".encode())
    return digest.hexdigest()


def picklable(*objects) -> bool:
    """Whether the objects can be sent to worker processes."""
    try:
        pickle.dumps(objects)
        return True
    except (TypeError, AttributeError, pickle.PicklingError):
        return False
