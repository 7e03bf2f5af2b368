"""Applications built on pyopenshowvar: the `kvp` command line (more to come: REPL, monitor, case studies)."""
