import os
import sys

# tests/ helpers (shapes.py) importable as plain modules
sys.path.insert(0, os.path.dirname(__file__))
