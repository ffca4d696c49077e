"""ROS 2 output: CDR messages serialized a block at a time (cdr, messages), written to MCAP chunks without a
per-message Python call (bag), in the axes and frames REP 103 and REP 105 ask for (conventions)."""
