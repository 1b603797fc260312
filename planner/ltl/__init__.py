"""LTL front end: parsing, simplification, translation to deterministic Rabin automata, HOA."""
