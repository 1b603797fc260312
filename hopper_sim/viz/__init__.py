"""Looking at runs: rerun recordings and their reader, the blueprint, figures, styles, the Table I
plot."""
