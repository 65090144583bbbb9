"""Machine profiles: pydantic models and TOML loading/saving."""

from cdprhost.profile.loader import (
    load_profile,
    profile_from_dict,
    profile_to_toml,
    resolve_profile_path,
    save_profile,
)
from cdprhost.profile.models import MachineProfile

__all__ = [
    "MachineProfile",
    "load_profile",
    "profile_from_dict",
    "profile_to_toml",
    "resolve_profile_path",
    "save_profile",
]
