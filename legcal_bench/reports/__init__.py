"""Reports that measure legcal-bench itself: the paper's reproductions, speed, the
static env's drift, and the regression fixture that pins today's numbers."""
