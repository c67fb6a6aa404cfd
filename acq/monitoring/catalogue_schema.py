"""The catalogue's schema (:mod:`acq.monitoring.catalogue`): the migrations that build it, one step per version.

Two tables. ``sessions`` holds what identifies a recording (id, path, joint, start time, tags, the monitor that
captured it); ``analyses`` one row per session and analysis request. A database records its version (SQLite's
``user_version``, a table on PostgreSQL: :mod:`acq.monitoring.catalogue_backends`);
:class:`~acq.monitoring.catalogue_db.CatalogueDatabase` applies the steps from there, each in its own transaction.
"""

from __future__ import annotations

#: Step i brings a database from version i to i + 1.
MIGRATIONS: tuple[str, ...] = (
    # 0 → 1: sessions and their analyses
    """
    CREATE TABLE sessions (
        session_key TEXT PRIMARY KEY,          -- session_id, or 'path:<path>' when the file is unreadable
        session_id TEXT, path TEXT NOT NULL, joint TEXT, created_utc TEXT, start_monotonic_ns INTEGER,
        status TEXT
    );
    CREATE TABLE analyses (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        session_key TEXT NOT NULL REFERENCES sessions(session_key),
        sha256 TEXT NOT NULL, request_key TEXT NOT NULL, options_json TEXT,
        analyzed_utc TEXT NOT NULL, acq_version TEXT, seconds REAL,
        verdict TEXT, reasons_json TEXT, error TEXT,
        K_Nm_per_rad REAL, K_lo REAL, K_hi REAL, Jm_kgm2 REAL, Jm_lo REAL, Jm_hi REAL,
        Jl_kgm2 REAL, Jl_lo REAL, Jl_hi REAL, C_Nms_per_rad REAL, C_lo REAL, C_hi REAL,
        f_a_hz REAL, f_r_hz REAL, clock_offset_s REAL, clock_drift_ppm REAL, clock_residual_s REAL,
        mean_coherence REAL, truth_json TEXT,
        UNIQUE (session_key, request_key)
    );
    """,
    # 1 → 2: session tags (pose, payload_kg, temperature_C, …) and a joint index for the trend
    """
    ALTER TABLE sessions ADD COLUMN tags_json TEXT NOT NULL DEFAULT '{}';
    CREATE INDEX sessions_joint ON sessions (joint, created_utc);
    """,
    # 2 → 3: results of a session's intact part only (damaged, or still recording; acq analyze --partial)
    """
    ALTER TABLE analyses ADD COLUMN partial INTEGER NOT NULL DEFAULT 0;
    """,
    # 3 → 4: which share of a window and which moves excite the joint (segment selection, acq monitor)
    """
    ALTER TABLE analyses ADD COLUMN excitation_json TEXT;
    """,
    # 4 → 5: the file each analysis was made of (copies of a session share its key: a damaged copy's failure must
    # not replace an intact copy's analysis)
    """
    ALTER TABLE analyses ADD COLUMN file_path TEXT;
    """,
    # 5 → 6: the monitor that captured a window (its tag MONITOR_TAG, as a column): a monitor reads back its own
    # windows of a catalogue every robot's joint1 shares by an index, not by reading every row of the joint's name.
    # Filled from the tags by CatalogueDatabase._fill_monitor_ids in the same transaction — in Python: tags_json is Python's
    # JSON, NaN included (--tag operator=Nan), which SQLite's json_extract and PostgreSQL's jsonb refuse
    """
    ALTER TABLE sessions ADD COLUMN monitor_id TEXT;
    CREATE INDEX sessions_monitor ON sessions (monitor_id, joint);
    """,
)
SCHEMA_VERSION = len(MIGRATIONS)
#: The schema version that has the column ``monitor_id`` (filled from the tags by the migration to it).
MONITOR_COLUMN_VERSION = 6
