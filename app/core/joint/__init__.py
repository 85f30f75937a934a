"""Joint angles between IMUs on the links of a hinge (numpy, no Qt): axis estimation from the
gyroscopes (:mod:`.axis`), the heading offset of two 6D orientations from the hinge
(:mod:`.heading`), the causal estimator (:mod:`.estimator`), whole recordings (:mod:`.offline`)
and time alignment of two recordings (:mod:`.alignment`)."""
