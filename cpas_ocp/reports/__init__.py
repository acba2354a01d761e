"""Reports and figures: the reconstruction's report folder, the failure report, the
reduction, diagnosis, comparison and discovery folders, the real-flight report, and the
figures each draws.
"""
