"""Type aliases shared by the tuning modules."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any, Union

import numpy as np

PathLike = Union[str, "os.PathLike[str]"]
Recording = tuple[np.ndarray, Mapping[str, Any]]
