"""Work on session files after recording: identify one (session → :mod:`analysis` → result), import the
files of other tools as a session, export a session to CSV.
"""
