"""The ground floor every layer may import: the error types (:mod:`acqcore.errors`).

``drivers`` and ``acq`` both import it, so the catalogue or the CSV reader need not import ``drivers``
for an error, and ``drivers`` still imports nothing of ``acq``. It imports nothing of ours itself;
``analysis`` (pure functions of arrays) does not need it.
"""
