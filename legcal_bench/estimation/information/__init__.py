"""Information: noise levels, whitening, observability, the posterior, stance design and the information gain."""
