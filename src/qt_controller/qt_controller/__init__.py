"""HRI Physio robot side: command protocol, QT robot controller and mock QT robot."""
