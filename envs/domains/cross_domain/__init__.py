"""Cross-domain clinical pathways: one episode, several phases, tools that switch with the phase."""
