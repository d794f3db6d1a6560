// igtl_force_reader.h - the test peers' reading side (igtl_plus_peer, igtl_hand_peer): every
// TRANSFORM named "Force" the client sends, its translation handed to `on_force`; anything
// else skipped. Returns when the connection ends (closed or broken).
#pragma once
#include <igtlClientSocket.h>
#include <igtlMessageHeader.h>
#include <igtlTransformMessage.h>

#include <cstring>

namespace isotouch::test {

/// on_force(fx, fy, fz): the Force TRANSFORM's translation (the force [N], the stream's frame).
template <class OnForce>
void read_forces(igtl::ClientSocket* sock, OnForce&& on_force) {
  for (;;) {
    igtl::MessageHeader::Pointer h = igtl::MessageHeader::New();
    h->InitPack();
    if (sock->Receive(h->GetPackPointer(), h->GetPackSize()) != h->GetPackSize()) return;
    h->Unpack();
    if (std::strcmp(h->GetDeviceType(), "TRANSFORM") != 0 || std::strcmp(h->GetDeviceName(), "Force") != 0) {
      sock->Skip(h->GetBodySizeToRead(), 0);
      continue;
    }
    igtl::TransformMessage::Pointer t = igtl::TransformMessage::New();
    t->SetMessageHeader(h);
    t->AllocatePack();
    if (sock->Receive(t->GetPackBodyPointer(), t->GetPackBodySize()) != t->GetPackBodySize()) return;
    if (!(t->Unpack(1) & igtl::MessageHeader::UNPACK_BODY)) continue;
    igtl::Matrix4x4 m;
    t->GetMatrix(m);
    on_force(m[0][3], m[1][3], m[2][3]);
  }
}

}  // namespace isotouch::test
