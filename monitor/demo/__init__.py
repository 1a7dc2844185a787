"""`fault-monitor demo`: the paper's comparison end to end (live daemons, Monte-Carlo, table, figures)."""
