"""The one hook kernels call on launch so a Tape can record them (None when no tape is recording)."""

recorder = None

# the ti.ad.FwdMode being entered (None outside): kernels launched meanwhile run their forward-mode instance
forward_mode = None
