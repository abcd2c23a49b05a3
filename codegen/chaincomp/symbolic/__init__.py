"""The chain's mathematics: truncated series of small errors (Freeman & Ford), jets for the
numeric derivatives, the derivation of the tool point's error, its printing, the exact numeric
model. Depends on chaincomp.model."""
