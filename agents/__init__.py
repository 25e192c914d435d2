"""Decision making: exploration, planning, merge coordination, rendezvous."""
