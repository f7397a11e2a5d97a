"""Physics components: smooth primitives, gas and restrictions, valves, the regulator, muscles, friction, signals."""
