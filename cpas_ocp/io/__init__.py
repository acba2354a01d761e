"""Files in and out: test folders (manifest and sensor CSVs), model blocks and model files,
flight-computer logs and flight cards, the built-in problems, and output folders written
all at once.
"""
