"""User-facing programs: the ``vjm`` command line and the thesis figure set."""
