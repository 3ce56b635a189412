"""The one hook kernels call on launch so a Tape can record them (None when no tape is recording)."""

recorder = None
