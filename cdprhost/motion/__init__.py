"""cdprhost.motion"""
