"""lfn_stream: light field networks with continuous levels of detail (not yet landed)."""
