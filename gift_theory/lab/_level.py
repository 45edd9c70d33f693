"""The lab's one significance level (reference §4): a goodness-of-fit test fails, a restricted map
is rejected, an identification test names its class and a design's power is reckoned at it."""

#: the level of every test the lab decides by
ALPHA = 0.01
