"""Where the model fails and what it lacks: residual tests and signatures, score tests of
the effects a model leaves out, the diagnosis, the air's motion, and the discovery chain
with the plug-ins it writes from signatures.
"""
