"""SITL harness of mppid: runs scenarios (simulator + mppid + lcm-logger in a private
network namespace), scores them, plots them, and runs campaigns of many seeds."""
