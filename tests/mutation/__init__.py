"""`make mutation`: mutmut over the modules that decide, each against the few test files that cover it."""
