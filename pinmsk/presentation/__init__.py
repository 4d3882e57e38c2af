"""What users see: figures, HTML reports, the meshcat viewer, progress bars and the CLI.

Nothing here runs an analysis of its own accord: it draws, prints or shows
results that the analyses (:mod:`pinmsk.solvers`, :mod:`pinmsk.diagnose`)
return.  The CLI (:mod:`.cli`) is the one place that calls analyses, because
it is the user's request.
"""
