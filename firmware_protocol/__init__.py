"""Wire protocol shared by the host and the (simulated) firmware."""
