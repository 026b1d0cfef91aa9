"""Decisions over time: N-best hypotheses, tracking, voting (consume any labeler's scores)."""
