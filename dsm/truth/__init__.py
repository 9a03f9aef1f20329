"""The exact side: the reference visibility, the oracles, the metrics and their intervals."""
