"""Parameter studies: where the kinks and jumps persist as system parameters change."""
