"""Names of ndt-cli's loggers.

Messages of the ``ndt_cli`` logger are held by the command line until the command ends (so that
a failing command prints one line); messages of :data:`PROGRESS` are shown as they come: the
progress of long work and what a user needs while it runs (a cluster's dashboard address)."""

PROGRESS = "ndt_cli.progress"
