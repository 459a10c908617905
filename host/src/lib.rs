//! `radiosity-host`: the workstation side of the radiosity toolkit.
