"""acq: record a robot joint's current and encoder, identify its stiffness K and inertias."""

from __future__ import annotations

__version__ = "0.1.0"
