"""Package data of pushbroom-explorer, installed as ``explorer.assets`` (see ``explorer/_resources.py``)."""
