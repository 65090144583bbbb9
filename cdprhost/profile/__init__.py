"""Machine profiles: pydantic models and TOML loading/saving."""

from cdprhost.profile.device_record import DeviceRecord
from cdprhost.profile.loader import (
    device_record_path,
    load_profile,
    profile_from_dict,
    profile_to_toml,
    record_device,
    resolve_profile_path,
    save_profile,
)
from cdprhost.profile.models import MachineProfile

__all__ = [
    "DeviceRecord",
    "MachineProfile",
    "device_record_path",
    "load_profile",
    "profile_from_dict",
    "profile_to_toml",
    "record_device",
    "resolve_profile_path",
    "save_profile",
]
