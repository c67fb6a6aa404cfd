"""What a person sees, and nothing it computes: the click command line, rich tables and value formats,
the pyqtgraph report (window and PNG), the live view, and the commands' screens. The numbers come
from the other packages.
"""
