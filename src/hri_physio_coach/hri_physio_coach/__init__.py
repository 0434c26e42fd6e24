"""HRI Physio scenario and adaptation: scenario engine, exercise coach, simulated participant."""
