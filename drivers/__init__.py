"""Hardware adapters (one module per transport) and the simulated bench.

Drivers never import :mod:`analysis` nor :mod:`acq`; vendor libraries (nidaqmx, canopen, pyserial)
are imported lazily by the adapter that needs them, through :mod:`drivers.registry`.
"""
