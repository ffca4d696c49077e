"""Live streaming, one concern a module: config (what a stream is asked to do), budget (what it needs of its link),
stream (one stream's encoding), producer (the process computing blocks ahead), inputs (serving a driver's
commands), streamer (the send loop and the run), realtime (pacer, lateness, SCHED_FIFO), transport/ (the links)."""
