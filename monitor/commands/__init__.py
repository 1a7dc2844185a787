"""One module per ``fault-monitor`` sub-command; each has ``register(subparsers)`` and keeps heavy imports lazy."""
