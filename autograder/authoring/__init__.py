"""The authoring tools: regenerating student notebooks and samples, mutation testing, the notebook runner,
the demo and ``new``. They use the core; the core never imports them.
"""
