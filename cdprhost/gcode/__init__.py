"""cdprhost.gcode"""
