"""URDFs we build, each with a README of its sources, and their shared generator pieces."""
