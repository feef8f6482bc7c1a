"""The real-time runtime of the nodes' loops: a rate loop on absolute deadlines (rate_loop), the causes of its
gaps (gap_causes), the garbage-collector policy that keeps collections out of the loops (garbage)."""
