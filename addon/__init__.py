"""Everything that imports bpy: properties, operators, panels, scene <-> core conversion."""
